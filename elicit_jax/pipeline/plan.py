"""Expand a pipeline definition into the stage graph of the filtering study.

Per task: collect D_base, one D_new per operator and the two contrast sets (held-out base
demos = compatible; demos of the known-conflicting operator = incompatible), each with its own
collection seed so the contrast sets never overlap a D_new. Per task × model: train the base
policy (all seeds in one stage: the policy library vmaps over seeds); per operator train on
D_base ∪ D_new (naive); score D_new and the contrast sets with the first seed's base policy, fit
(λ, η) on the contrast scores, filter D_new (M-filter and baseline filters), retrain on
D_base ∪ filtered (all seeds), evaluate every policy (all seeds and checkpoints); draw the
maps; one report.

The curation baselines add, per operator, a ``deminf`` stage (per task: DemInf needs no
policy) or a ``demo-score`` stage (per task × model: it rolls out the naive policy of that
operator), whose per-demonstration scores ``curate`` stages cut at the method's own rule or at
the M-filter's budget. A ``[sensitivity]`` table adds the λ study: ``lambda-point`` stages place
λ across the fit's margin, and base, naive and M-filtered policies per point are trained on
held-out seeds and evaluated on held-out initial states.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.curation_stages import cupid_plan, per_demo_source, quality_plan
from elicit_jax.pipeline.graph import Graph, Stage
from elicit_jax.pipeline.spec import CURATION_METHODS, METHODS, PipelineSpec, TaskSpec

FILTER_METHODS = tuple(m for m in METHODS if m not in ("base", "naive"))
M_FILTER_METHODS = tuple(m for m in FILTER_METHODS if m not in CURATION_METHODS)
COLLECT_SEED_OFFSETS = {"base": 0, "holdout": 1, "incompatible": 2}
NEW_SEED_OFFSET = 10

ConfigResolver = Callable[[str, dict[str, Any]], dict[str, Any]]


def _identity(kind: str, raw: dict[str, Any]) -> dict[str, Any]:
    return raw


def collect_seed(spec: PipelineSpec, task: TaskSpec, role: str) -> int:
    """Collection seed of a demo set: distinct per role and operator, so sets never overlap."""
    if role in COLLECT_SEED_OFFSETS:
        return spec.collect_seed + COLLECT_SEED_OFFSETS[role]
    return spec.collect_seed + NEW_SEED_OFFSET + task.operators.index(role)


def threshold_stages(
    spec: Any, task: Any, model: str, base_policy: str, resolve: ConfigResolver
) -> tuple[Stage, Stage]:
    """Score the contrast sets (held-out base demos, the known-incompatible operator's demos)
    with the first seed's base policy of stage ``base_policy``, and fit (λ, η) on them.

    ``spec`` and ``task`` are a filtering pipeline's or an elicitation study's: both have
    ``seeds``, ``collect_seed`` and ``section``, and ``name``, ``base_operator`` and
    ``incompatible_operator``.
    """
    t = task.name
    cell, where = f"{t}/{model}", {"task": t, "model": model}
    score_raw = {**spec.section("score"), **where, "policy_seed": spec.seeds[0]}
    contrast = Stage(
        id=f"score/{cell}/contrast",
        kind="score",
        output=f"scores/{cell}/contrast",
        config=resolve("score", {**score_raw, "set": "contrast"}),
        inputs={
            "policy": base_policy,
            "demos0": f"collect/{t}/holdout",
            "demos1": f"collect/{t}/incompatible",
        },
        label=f"score {t} {model} contrast sets",
    )
    fit = Stage(
        id=f"fit-thresholds/{cell}",
        kind="fit-thresholds",
        output=f"thresholds/{cell}.json",
        config=resolve(
            "fit-thresholds",
            {
                **spec.section("thresholds"),
                **where,
                "compatible_operator": task.base_operator,
                "incompatible_operator": task.incompatible_operator,
                "holdout_seed": spec.collect_seed + COLLECT_SEED_OFFSETS["holdout"],
                "incompatible_seed": spec.collect_seed + COLLECT_SEED_OFFSETS["incompatible"],
            },
        ),
        inputs={"scores": contrast.id},
        label=f"fit thresholds {t} {model}",
    )
    return contrast, fit


def build_graph(spec: PipelineSpec, resolve: ConfigResolver = _identity) -> Graph:
    """The stage graph of ``spec``.

    Args:
      spec: the parsed definition.
      resolve: ``(kind, raw_config) -> config``; the real stages turn overrides into their
        library's full config here (validating field names), so a changed default re-runs.
    """
    stages: list[Stage] = []
    needs_scores = any(m in FILTER_METHODS for m in spec.methods)
    for task in spec.tasks:
        stages += _collect_stages(spec, task, resolve, needs_scores)
        stages += _deminf_stages(spec, task, resolve)
        stages += quality_plan(spec, task, resolve)
        for model in spec.models:
            stages += _cell_stages(spec, task, model, needs_scores, resolve)
    report_kinds = (
        "collect",
        "fit-thresholds",
        "evaluate",
        "map",
        "filter",
        "curate",
        "deminf",
        "demo-score",
        "cupid",
        "quality",
        "lambda-point",
        "lambda-valley",
    )
    report_inputs = {s.id: s.id for s in stages if s.kind in report_kinds}
    stages.append(
        Stage(
            id="report",
            kind="report",
            output="report",
            config=resolve(
                "report",
                {
                    **spec.section("report"),
                    "pipeline": spec.name,
                    "profile": spec.profile,
                    "spec_text": spec.text,
                },
            ),
            inputs=report_inputs,
            label="report",
        )
    )
    return Graph(stages)


def _collect_stages(
    spec: PipelineSpec, task: TaskSpec, resolve: ConfigResolver, contrast: bool = True
) -> list[Stage]:
    """D_base, each D_new and (when thresholds are fitted) the two contrast sets."""
    sets = [("base", task.base_operator, task.base_episodes, "base")]
    if contrast:
        sets += [
            ("holdout", task.base_operator, task.holdout_episodes, "contrast-compatible"),
            (
                "incompatible",
                task.incompatible_operator,
                task.incompatible_episodes,
                "contrast-incompatible",
            ),
        ]
    sets += [(op, op, task.new_episodes, f"new-{op}") for op in task.operators]
    out = []
    for role, operator, episodes, name in sets:
        seed = collect_seed(spec, task, role)
        raw = {
            **spec.section("collect"),
            "task": task.name,
            "operator": operator,
            "episodes": episodes,
            "seed": seed,
            "role": role if role in COLLECT_SEED_OFFSETS else "new",
        }
        sid = f"collect/{task.name}/{role if role in COLLECT_SEED_OFFSETS else 'new/' + role}"
        out.append(
            Stage(
                id=sid,
                kind="collect",
                output=f"data/{task.name}/{name}.parquet",
                config=resolve("collect", raw),
                seed=seed,
                label=f"collect {task.name} {name} ({episodes} demos of {operator})",
            )
        )
    return out


def _deminf_stages(spec: PipelineSpec, task: TaskSpec, resolve: ConfigResolver) -> list[Stage]:
    """DemInf scores of each D_new over D_base ∪ D_new (no policy: one stage per task)."""
    if not any(m.startswith("deminf") for m in spec.methods):
        return []
    t = task.name
    return [
        Stage(
            id=f"deminf/{t}/{op}",
            kind="deminf",
            output=f"curation/{t}/deminf-{op}.parquet",
            config=resolve("deminf", {**spec.section("deminf"), "task": t, "operator": op}),
            inputs={"demos0": f"collect/{t}/base", "demos1": f"collect/{t}/new/{op}"},
            label=f"deminf {t} D_new of {op}",
        )
        for op in task.operators
    ]


class _Cell:
    """Stage builders of one task × model cell."""

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
        return f"collect/{self.t}/new/{op}"


def _cell_stages(
    spec: PipelineSpec, task: TaskSpec, model: str, needs_scores: bool, resolve: ConfigResolver
) -> list[Stage]:
    c = _Cell(spec, task, model, resolve)
    stages: list[Stage] = []
    base = c.train("base", None, {})
    stages += [base, c.evaluate(base, "base", None)]
    naive: dict[str, Stage] = {}
    for op in task.operators:
        if "naive" in spec.methods:
            naive[op] = c.train("naive", op, {"demos1": c.new(op)})
            stages += [naive[op], c.evaluate(naive[op], "naive", op)]
    if not needs_scores:
        return stages
    score_raw = {**spec.section("score"), **c.where, "policy_seed": spec.seeds[0]}
    contrast, fit = threshold_stages(spec, task, model, base.id, resolve)
    stages += [contrast, fit]
    map_inputs = {"thresholds": fit.id, "scores:contrast": contrast.id}
    scores: dict[str, Stage] = {}
    for op in task.operators:
        score = scores[op] = Stage(
            id=f"score/{c.cell}/{op}",
            kind="score",
            output=f"scores/{c.cell}/new-{op}",
            config=resolve("score", {**score_raw, "set": op}),
            inputs={"policy": base.id, "demos0": c.new(op)},
            label=f"score {c.t} {model} D_new of {op}",
        )
        stages.append(score)
        map_inputs[f"scores:{op}"] = score.id
        demo_score = None
        if any(m.startswith("demo-score") for m in spec.methods):
            demo_score = _demo_score_stage(c, op, naive[op])
            stages.append(demo_score)
        cupid = None
        if any(m.startswith("cupid") for m in spec.methods):
            cupid = cupid_plan(spec, task, model, op, naive[op], resolve)
            stages.append(cupid)
        for method in (m for m in FILTER_METHODS if m in spec.methods):
            if method == "filtered-valley":
                continue  # needs every operator's scores: below
            if method in CURATION_METHODS:
                sources = {"demo-score": demo_score, "cupid": cupid}
                per_demo = per_demo_source(method, c.t, op, sources)
                filt = c.curate(method, op, per_demo, score, fit)
            else:
                filt = c.filter(method, op, score, fit.id)
            trained = c.train(method, op, {"demos1": filt.id})
            stages += [filt, trained, c.evaluate(trained, method, op)]
    if "filtered-valley" in spec.methods:
        valley = Stage(
            id=f"lambda-valley/{c.cell}",
            kind="lambda-valley",
            output=f"thresholds/{c.cell}-valley.json",
            config=resolve("lambda-valley", {**c.where}),
            inputs={"thresholds": fit.id, **{f"scores:{op}": s.id for op, s in scores.items()}},
            label=f"λ by the new-data valley rule {c.t} {model}",
        )
        stages.append(valley)
        for op in task.operators:
            filt = c.filter("filtered-valley", op, scores[op], valley.id)
            trained = c.train("filtered-valley", op, {"demos1": filt.id})
            stages += [filt, trained, c.evaluate(trained, "filtered-valley", op)]
    stages.append(
        Stage(
            id=f"map/{c.cell}",
            kind="map",
            output=f"maps/{c.t}-{model}.png",
            config=resolve(
                "map",
                {**c.where, "operators": list(task.operators), "base_operator": task.base_operator},
            ),
            inputs=map_inputs,
            label=f"map {c.t} {model}",
        )
    )
    sens = spec.sensitivity
    if sens is not None and (not sens.tasks or task.name in sens.tasks):
        stages += _sensitivity_stages(c, scores, fit)
    return stages


def _demo_score_stage(c: _Cell, op: str, naive: Stage) -> Stage:
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


def _sensitivity_stages(c: _Cell, scores: Mapping[str, Stage], fit: Stage) -> list[Stage]:
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
