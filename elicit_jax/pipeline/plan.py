"""Expand a pipeline definition into the stage graph of the filtering study.

Per task: collect D_base, one D_new per operator and the two contrast sets (held-out base
demos = compatible; demos of the known-conflicting operator = incompatible), each with its own
collection seed so the contrast sets never overlap a D_new. Per task × model: train the base
policy (all seeds in one stage: the policy library vmaps over seeds); per operator train on
D_base ∪ D_new (naive); score D_new and the contrast sets with the first seed's base policy, fit
(λ, η) on the contrast scores, filter D_new (M-filter and baseline filters), retrain on
D_base ∪ filtered (all seeds), evaluate every policy (all seeds and checkpoints); draw the
maps; one report.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from elicit_jax.pipeline.graph import Graph, Stage
from elicit_jax.pipeline.spec import METHODS, PipelineSpec, TaskSpec

FILTER_METHODS = tuple(m for m in METHODS if m not in ("base", "naive"))
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
        stages += _collect_stages(spec, task, resolve)
        for model in spec.models:
            stages += _cell_stages(spec, task, model, needs_scores, resolve)
    report_inputs = {
        s.id: s.id for s in stages if s.kind in ("collect", "fit-thresholds", "evaluate", "map")
    }
    report_inputs |= {s.id: s.id for s in stages if s.kind == "filter"}
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


def _collect_stages(spec: PipelineSpec, task: TaskSpec, resolve: ConfigResolver) -> list[Stage]:
    sets = [
        ("base", task.base_operator, task.base_episodes, "base"),
        ("holdout", task.base_operator, task.holdout_episodes, "contrast-compatible"),
        (
            "incompatible",
            task.incompatible_operator,
            task.incompatible_episodes,
            "contrast-incompatible",
        ),
    ] + [(op, op, task.new_episodes, f"new-{op}") for op in task.operators]
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


def _cell_stages(
    spec: PipelineSpec, task: TaskSpec, model: str, needs_scores: bool, resolve: ConfigResolver
) -> list[Stage]:
    t = task.name
    cell = f"{t}/{model}"
    base_data = f"collect/{t}/base"
    where = {"task": t, "model": model}
    score_seed = spec.seeds[0]
    stages: list[Stage] = []

    def train(method: str, op: str | None, extra: Mapping[str, str]) -> Stage:
        suffix = method if op is None else f"{method}/{op}"
        raw = {**spec.section("train"), **where, "seeds": list(spec.seeds)}
        raw |= {"profile": spec.profile, "method": method, "operator": op}
        return Stage(
            id=f"train/{cell}/{suffix}",
            kind="train",
            output=f"policies/{cell}/{suffix.replace('/', '-')}",
            config=resolve("train", raw),
            inputs={"demos0": base_data, **extra},
            label=f"train {t} {model} {suffix} (seeds {_seeds(spec)})",
        )

    def evaluate(train_stage: Stage, method: str, op: str | None) -> Stage:
        suffix = method if op is None else f"{method}-{op}"
        raw = {**spec.section("evaluate"), **where, "seeds": list(spec.seeds)}
        raw |= {"profile": spec.profile, "method": method, "operator": op}
        return Stage(
            id=f"evaluate/{cell}/{suffix}",
            kind="evaluate",
            output=f"evals/{cell}/{suffix}.parquet",
            config=resolve("evaluate", raw),
            inputs={"policy": train_stage.id},
            label=f"evaluate {t} {model} {suffix}",
        )

    base = train("base", None, {})
    stages += [base, evaluate(base, "base", None)]
    for op in task.operators:
        if "naive" in spec.methods:
            naive = train("naive", op, {"demos1": f"collect/{t}/new/{op}"})
            stages += [naive, evaluate(naive, "naive", op)]
    if not needs_scores:
        return stages
    score_raw = {**spec.section("score"), **where, "policy_seed": score_seed}
    contrast = Stage(
        id=f"score/{cell}/contrast",
        kind="score",
        output=f"scores/{cell}/contrast",
        config=resolve("score", {**score_raw, "set": "contrast"}),
        inputs={
            "policy": base.id,
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
                "holdout_seed": collect_seed(spec, task, "holdout"),
                "incompatible_seed": collect_seed(spec, task, "incompatible"),
            },
        ),
        inputs={"scores": contrast.id},
        label=f"fit thresholds {t} {model}",
    )
    stages += [contrast, fit]
    map_inputs = {"thresholds": fit.id, "scores:contrast": contrast.id}
    for op in task.operators:
        score = Stage(
            id=f"score/{cell}/{op}",
            kind="score",
            output=f"scores/{cell}/new-{op}",
            config=resolve("score", {**score_raw, "set": op}),
            inputs={"policy": base.id, "demos0": f"collect/{t}/new/{op}"},
            label=f"score {t} {model} D_new of {op}",
        )
        stages.append(score)
        map_inputs[f"scores:{op}"] = score.id
        for method in (m for m in FILTER_METHODS if m in spec.methods):
            inputs = {"scores": score.id, "thresholds": fit.id, "demos": f"collect/{t}/new/{op}"}
            filt = Stage(
                id=f"filter/{cell}/{method}/{op}",
                kind="filter",
                output=f"filtered/{cell}/{method}-{op}",
                config=resolve(
                    "filter",
                    {**spec.section("filter"), **where, "method": method, "operator": op},
                ),
                inputs=inputs,
                seed=spec.collect_seed,
                label=f"filter {t} {model} {op} ({method})",
            )
            trained = train(method, op, {"demos1": filt.id})
            stages += [filt, trained, evaluate(trained, method, op)]
    stages.append(
        Stage(
            id=f"map/{cell}",
            kind="map",
            output=f"maps/{t}-{model}.png",
            config=resolve(
                "map",
                {**where, "operators": list(task.operators), "base_operator": task.base_operator},
            ),
            inputs=map_inputs,
            label=f"map {t} {model}",
        )
    )
    return stages


def _seeds(spec: PipelineSpec) -> str:
    return ",".join(str(s) for s in spec.seeds)
