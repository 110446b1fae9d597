"""The stage builders of one task × model cell of the filtering study (:class:`Cell`): train,
evaluate, filter and curate stages with their ids and outputs; the scoring policy's training
(:func:`scorer_stage`); the Demo-SCORE stage of an operator; and the λ-sensitivity study's
stages (:func:`sensitivity_stages`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.gather import SCORER_METHOD
from elicit_jax.pipeline.graph import Stage
from elicit_jax.pipeline.spec import PipelineSpec, TaskSpec

ConfigResolver = Callable[[str, dict[str, Any]], dict[str, Any]]
"""``(kind, raw_config) -> config``: turns a stage's overrides into its full config."""


class Cell:
    """Stage builders of one task × model cell (its spec, task, model and config resolver)."""

    def __init__(
        self, spec: PipelineSpec, task: TaskSpec, model: str, resolve: ConfigResolver
    ) -> None:
        self.spec, self.task, self.model, self.resolve = spec, task, model, resolve
        self.t = task.name
        self.cell = f"{task.name}/{model}"
        self.where = {"task": task.name, "model": model}

    def train(
        self,
        method: str,
        op: str | None,
        extra: Mapping[str, str],
        seeds: tuple[int, ...] | None = None,
        prefix: str = "",
        meta: Mapping[str, Any] | None = None,
    ) -> Stage:
        seeds = seeds or self.spec.seeds
        suffix = prefix + (method if op is None else f"{method}/{op}")
        raw = {**self.spec.section("train"), **self.where, "seeds": list(seeds)}
        raw |= {"profile": self.spec.profile, "method": method, "operator": op, **(meta or {})}
        return Stage(
            id=f"train/{self.cell}/{suffix}",
            kind="train",
            output=f"policies/{self.cell}/{suffix.replace('/', '-')}",
            config=self.resolve("train", raw),
            inputs={"demos0": f"collect/{self.t}/base", **extra},
            label=f"train {self.t} {self.model} {suffix} (seeds {_seeds(seeds)})",
        )

    def evaluate(
        self,
        train_stage: Stage,
        method: str,
        op: str | None,
        held_out: bool = False,
        prefix: str = "",
        meta: Mapping[str, Any] | None = None,
    ) -> Stage:
        """Evaluate every seed and checkpoint of a training run (the held-out study: its seeds
        and initial states)."""
        sens = self.spec.sensitivity
        seeds = sens.seeds if held_out and sens else self.spec.seeds
        suffix = prefix.replace("/", "-") + (method if op is None else f"{method}-{op}")
        raw = {**self.spec.section("evaluate"), **self.where, "seeds": list(seeds)}
        raw |= {"profile": self.spec.profile, "method": method, "operator": op, **(meta or {})}
        if held_out and sens:
            raw["seed"] = sens.eval_seed
        return Stage(
            id=f"evaluate/{self.cell}/{suffix}",
            kind="evaluate",
            output=f"evals/{self.cell}/{suffix}.parquet",
            config=self.resolve("evaluate", raw),
            inputs={"policy": train_stage.id},
            label=f"evaluate {self.t} {self.model} {suffix}",
        )

    def filter(
        self, method: str, op: str, score: Stage, thresholds: str, prefix: str = ""
    ) -> Stage:
        """An M-filter or baseline filter of one D_new under the thresholds of a stage."""
        return Stage(
            id=f"filter/{self.cell}/{prefix}{method}/{op}",
            kind="filter",
            output=f"filtered/{self.cell}/{prefix.replace('/', '-')}{method}-{op}",
            config=self.resolve(
                "filter",
                {**self.spec.section("filter"), **self.where, "method": method, "operator": op},
            ),
            inputs={"scores": score.id, "thresholds": thresholds, "demos": self.new(op)},
            seed=self.spec.collect_seed,
            label=f"filter {self.t} {self.model} {op} ({prefix}{method})",
        )

    def curate(self, method: str, op: str, scores: str, score: Stage, fit: Stage) -> Stage:
        """DemInf / Demo-SCORE cut of one D_new: own rule, or the M-filter's budget."""
        raw = {**self.where, "method": method, "operator": op}
        raw |= {"filter": self.spec.section("filter"), "deminf": self.spec.section("deminf")}
        return Stage(
            id=f"filter/{self.cell}/{method}/{op}",
            kind="curate",
            output=f"filtered/{self.cell}/{method}-{op}",
            config=self.resolve("curate", raw),
            inputs={
                "episode_scores": scores,
                "scores": score.id,
                "thresholds": fit.id,
                "demos": self.new(op),
            },
            label=f"curate {self.t} {self.model} {op} ({method})",
        )

    def new(self, op: str) -> str:
        """The id of the stage that collects ``op``'s D_new."""
        return f"collect/{self.t}/new/{op}"


def scorer_stage(c: Cell) -> Stage:
    """The policy that scores the contrast sets and every D_new of the cell, when the
    definition has ``[scorer]``: trained on D_base, one seed (the first training seed, which
    the score stages read), with the scorer's own training profile and options (``[train]``
    does not apply to it)."""
    scorer = c.spec.scorer
    assert scorer is not None
    seed = c.spec.seeds[0]
    raw = {**scorer.settings, **c.where, "seeds": [seed]}
    raw |= {"profile": scorer.profile, "method": SCORER_METHOD, "operator": None}
    return Stage(
        id=f"train/{c.cell}/{SCORER_METHOD}",
        kind="train",
        output=f"policies/{c.cell}/{SCORER_METHOD}",
        config=c.resolve("train", raw),
        inputs={"demos0": f"collect/{c.t}/base"},
        label=f"train {c.t} {c.model} {SCORER_METHOD} ({scorer.profile} profile, seed {seed})",
    )


def demo_score_stage(c: Cell, op: str, naive: Stage) -> Stage:
    """Demo-SCORE scores of ``op``'s D_new from rollouts of its naive policy."""
    raw = {**c.spec.section("demo_score"), **c.where, "operator": op}
    raw |= {"policy_seed": c.spec.seeds[0]}
    return Stage(
        id=f"demo-score/{c.cell}/{op}",
        kind="demo-score",
        output=f"curation/{c.cell}/demo-score-{op}.parquet",
        config=c.resolve("demo-score", raw),
        inputs={"policy": naive.id, "demos": c.new(op)},
        label=f"demo-score {c.t} {c.model} D_new of {op} (rollouts of its naive policy)",
    )


def sensitivity_stages(c: Cell, scores: Mapping[str, Stage], fit: Stage) -> list[Stage]:
    """Base, naive and M-filtered at each λ point, on held-out training and evaluation seeds."""
    sens = c.spec.sensitivity
    assert sens is not None
    ops = sens.operators or c.task.operators
    unknown = [op for op in ops if op not in c.task.operators]
    if unknown:
        raise ElicitError(
            f"[sensitivity] operators {', '.join(unknown)} are not operators of {c.t}"
        )
    seeds = sens.seeds
    meta = {"study": "sensitivity"}
    base = c.train("base", None, {}, seeds, "heldout/", meta)
    stages = [base, c.evaluate(base, "base", None, True, "heldout/", meta)]
    for op in ops:
        naive = c.train("naive", op, {"demos1": c.new(op)}, seeds, "heldout/", meta)
        stages += [naive, c.evaluate(naive, "naive", op, True, "heldout/", meta)]
    for k in range(sens.points):
        point = Stage(
            id=f"lambda-point/{c.cell}/{k}",
            kind="lambda-point",
            output=f"thresholds/{c.cell}-lambda{k}.json",
            config=c.resolve("lambda-point", {**c.where, "point": k, "points": sens.points}),
            inputs={"thresholds": fit.id},
            label=f"λ point {k + 1}/{sens.points} of {c.t} {c.model}",
        )
        stages.append(point)
        prefix = f"heldout/lambda{k}/"
        for op in ops:
            filt = c.filter("filtered", op, scores[op], point.id, prefix)
            point_meta = {**meta, "point": k}
            trained = c.train("filtered", op, {"demos1": filt.id}, seeds, prefix, point_meta)
            held = c.evaluate(trained, "filtered", op, True, prefix, point_meta)
            stages += [filt, trained, held]
    return stages


def _seeds(seeds: tuple[int, ...]) -> str:
    return ",".join(str(s) for s in seeds)
