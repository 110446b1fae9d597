"""Expand a pipeline definition into the stage graph of the filtering study.

Per task: collect D_base, one D_new per operator and the two contrast sets (held-out base
demos = compatible; demos of the known-conflicting operator = incompatible), each with its own
collection seed so the contrast sets never overlap a D_new. Per task × model: train the base
policy (all seeds in one stage: the policy library vmaps over seeds); per operator train on
D_base ∪ D_new (naive); score the contrast sets with the first seed's base policy, fit (λ, η)
on their scores, score each D_new under the fitted (λ, η), filter D_new (M-filter and baseline
filters), retrain on D_base ∪ filtered (all seeds), evaluate every policy (all seeds and
checkpoints); draw the maps; one report. With a ``[scorer]`` table a policy of its own scores
instead of the base policy: trained on the same D_base, the first seed only, with the scorer's
training settings (``train/<task>/<model>/scorer``: :func:`~.plan_cell.scorer_stage`); when
those train exactly as the base policy does (seeds aside), the base policy is that scorer and
none is planned.

A ``[collections]`` table repeats every task's chain, from collection to evaluation, on other
collections of the same demo sets (:func:`collection_specs`): collection 0 keeps the ids and
outputs of a single-collection study, collection ``c`` has ``c<c>/`` in its own.

The curation baselines add, per operator, a ``deminf`` stage (per task: DemInf needs no
policy) or a ``demo-score`` stage (per task × model: it rolls out the naive policy of that
operator), whose per-demonstration scores ``curate`` stages cut at the method's own rule or at
the M-filter's budget. A ``[sensitivity]`` table adds the λ study: ``lambda-point`` stages place
λ across the fit's margin, and base, naive and M-filtered policies per point are trained on
held-out seeds and evaluated on held-out initial states.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.curation_stages import cupid_plan, operator_stages, per_demo_source
from elicit_jax.pipeline.gather import REPORT_STAGE
from elicit_jax.pipeline.graph import Graph, Stage
from elicit_jax.pipeline.plan_cell import (
    Cell,
    ConfigResolver,
    demo_score_stage,
    scorer_stage,
    sensitivity_stages,
)
from elicit_jax.pipeline.sizes import DEFAULT_SIZES, dict_of, in_sizes, sized_specs
from elicit_jax.pipeline.spec import CURATION_METHODS, METHODS, PipelineSpec, TaskSpec
from elicit_jax.pipeline.stage_kind import StageKinds
from elicit_jax.pipeline.stages import FILTERING_KINDS
from elicit_jax.sim.operators import episode_traits

FILTER_METHODS = tuple(m for m in METHODS if m not in ("base", "naive"))
M_FILTER_METHODS = tuple(m for m in FILTER_METHODS if m not in CURATION_METHODS)
COLLECT_SEED_OFFSETS = {"base": 0, "holdout": 1, "incompatible": 2}
NEW_SEED_OFFSET = 10
COLLECTION_STRIDE = 100
"""Collection ``c`` collects with seeds ``collect_seed + COLLECTION_STRIDE · c + offset``."""
FILTERING = StageKinds(FILTERING_KINDS)
"""The filtering study's stage kinds (what this planner places)."""
REPORTED = FILTERING.reported()
"""The stage kinds the report stage reads
(:attr:`~elicit_jax.pipeline.stage_kind.StageKind.reported`)."""


def unresolved(kind: str, raw: dict[str, Any]) -> dict[str, Any]:
    """The config resolver that keeps every raw config (a graph's shape, without the
    registry's validation: :meth:`~elicit_jax.pipeline.stage_kind.StageKinds.resolve`)."""
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
    with the first seed of the policy trained by stage ``base_policy`` (the base policy, or
    the filtering study's scorer), and fit (λ, η) on them.

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


def build_graph(spec: PipelineSpec, resolve: ConfigResolver = unresolved) -> Graph:
    """The stage graph of ``spec``: each collection's per-task chains, then one report.

    Args:
      spec: the parsed definition.
      resolve: ``(kind, raw_config) -> config``; the real stages turn overrides into their
        library's full config here (validating field names), so a changed default re-runs.
    """
    stages: list[Stage] = []
    for name, sized in sized_specs(spec):
        part: list[Stage] = []
        for number, sub in collection_specs(sized):
            part += collection_stages(sub, number, _sized_resolver(resolve, name))
        stages += [in_sizes(s, name, FILTERING[s.kind].side_by_side) for s in part]
    stages.append(report_stage(spec, REPORT_STAGE, stages, REPORTED, resolve))
    return Graph(stages)


def _sized_resolver(resolve: ConfigResolver, name: str) -> ConfigResolver:
    """``resolve`` recording the sizes ``name`` in every config (none for the default sizes,
    whose stages keep the identities of a run without sizes)."""
    if name == DEFAULT_SIZES:
        return resolve
    return lambda kind, raw: resolve(kind, {**raw, "sizes": name})


def report_stage(
    spec: Any, kind: str, stages: list[Stage], reads: tuple[str, ...], resolve: ConfigResolver
) -> Stage:
    """The one report stage of a study (a filtering pipeline's or an elicitation study's):
    stage ``kind``, reading every stage of ``stages`` whose kind is in ``reads``.

    ``spec`` has ``name``, ``profile``, ``text`` and ``section``.
    """
    raw = {**spec.section("report"), "pipeline": spec.name, "profile": spec.profile}
    sizes = getattr(spec, "sizes", (DEFAULT_SIZES,))
    if sizes != (DEFAULT_SIZES,):  # each sizes' counts per task, as the report states them
        raw["sizes"] = {n: {t.name: list(dict_of(t)[n]) for t in spec.tasks} for n in sizes}
    return Stage(
        id="report",
        kind=kind,
        output="report",
        config=resolve(kind, {**raw, "spec_text": spec.text}),
        inputs={s.id: s.id for s in stages if s.kind in reads},
        label="report",
    )


def collection_specs(spec: PipelineSpec) -> list[tuple[int, PipelineSpec]]:
    """Each collection of the study and the spec its stages are planned from.

    Without ``[collections]``: the definition's one collection (number 0). With it: per
    collection seed ``c``, the definition with ``collect_seed`` moved by
    ``COLLECTION_STRIDE · c`` (every demo set of a collection has its own seeds, disjoint from
    every other collection's); the first collection runs the full ``methods`` and the
    λ-sensitivity study, the others the ``[collections] methods``.
    """
    coll = spec.collections
    if coll is None:
        return [(0, spec)]
    most = max(len(t.operators) for t in spec.tasks)
    if NEW_SEED_OFFSET + most > COLLECTION_STRIDE:
        raise ElicitError(
            f"[collections] supports at most {COLLECTION_STRIDE - NEW_SEED_OFFSET} operators "
            "per task (each D_new needs its own collection seed)",
            spec.source,
        )
    out = []
    for i, c in enumerate(coll.seeds):
        first = i == 0
        out.append(
            (
                c,
                dataclasses.replace(
                    spec,
                    collect_seed=spec.collect_seed + COLLECTION_STRIDE * c,
                    methods=spec.methods if first else coll.methods,
                    sensitivity=spec.sensitivity if first else None,
                    collections=None,
                ),
            )
        )
    return out


def collection_stages(spec: PipelineSpec, number: int, resolve: ConfigResolver) -> list[Stage]:
    """Every task's stages in collection ``number`` (``spec`` is that collection's, from
    :func:`collection_specs`). Collection 0 keeps the stage ids, outputs and configs of a
    single-collection study; collection ``c`` puts ``c<c>/`` after the first part of every id
    and output (``collect/c1/square-nut/base``, ``data/c1/square-nut/base.parquet``) and records
    ``collection = c`` in every config."""
    if number != 0:
        inner = resolve

        def resolve(kind: str, raw: dict[str, Any]) -> dict[str, Any]:
            return inner(kind, {**raw, "collection": number})

    stages: list[Stage] = []
    needs_scores = any(m in FILTER_METHODS for m in spec.methods)
    for task in spec.tasks:
        stages += _collect_stages(spec, task, resolve, needs_scores)
        stages += operator_stages(spec, task, "deminf", "deminf", resolve, over_base=True)
        stages += operator_stages(spec, task, "quality", "quality flags", resolve)
        for model in spec.models:
            stages += _cell_stages(spec, task, model, needs_scores, resolve)
    return stages if number == 0 else [in_collection(s, number) for s in stages]


def in_collection(stage: Stage, number: int) -> Stage:
    """``stage`` moved into collection ``number``: ``c<number>/`` after the first part of its
    id, output and input ids (a kind whose outputs sit side by side, a map:
    ``maps/c<number>-<name>.png``, as reports keep maps under their file names)."""
    return stage.moved(f"c{number}", FILTERING[stage.kind].side_by_side, f"c{number}")


VERIFIED_ROLES = {"holdout": "no-conflict", "incompatible": "conflicts"}
"""What a contrast set's demos must show, measured per demo, on tasks that measure traits
(:func:`elicit_jax.sim.operators.episode_traits`): held-out base demos that do not conflict,
known-incompatible demos that do."""


def contrast_sets(task: Any, names: tuple[str, str]) -> list[tuple[str, str, int, str]]:
    """The two contrast sets of a task (held-out base demos, the incompatible operator's) as
    ``(role, operator, episodes, file name)``, their files named ``names``; on tasks that
    measure episode traits their collect stages keep only verified demos
    (:data:`VERIFIED_ROLES`)."""
    return [
        ("holdout", task.base_operator, task.holdout_episodes, names[0]),
        ("incompatible", task.incompatible_operator, task.incompatible_episodes, names[1]),
    ]


def collect_stages(
    spec: Any, task: Any, sets: list[tuple[str, str, int, str]], resolve: ConfigResolver
) -> list[Stage]:
    """One ``collect`` stage per demo set ``(role, operator, episodes, file name)`` of a task
    (a role of :data:`COLLECT_SEED_OFFSETS`, or a new operator's name), each with its own
    collection seed (:func:`collect_seed`)."""
    out = []
    for role, operator, episodes, name in sets:
        seed = collect_seed(spec, task, role)
        kept = role if role in COLLECT_SEED_OFFSETS else "new"
        raw = {**spec.section("collect"), "task": task.name, "operator": operator}
        raw |= {"episodes": episodes, "seed": seed, "role": kept}
        if role in VERIFIED_ROLES and episode_traits(task.name) is not None:
            raw["require"] = VERIFIED_ROLES[role]
        out.append(
            Stage(
                id=f"collect/{task.name}/{role if kept == role else 'new/' + role}",
                kind="collect",
                output=f"data/{task.name}/{name}.parquet",
                config=resolve("collect", raw),
                seed=seed,
                label=f"collect {task.name} {name} ({episodes} demos of {operator})",
            )
        )
    return out


def _collect_stages(
    spec: PipelineSpec, task: TaskSpec, resolve: ConfigResolver, contrast: bool = True
) -> list[Stage]:
    """D_base, each D_new and (when thresholds are fitted) the two contrast sets."""
    sets = [("base", task.base_operator, task.base_episodes, "base")]
    if contrast:
        sets += contrast_sets(task, ("contrast-compatible", "contrast-incompatible"))
    sets += [(op, op, task.new_episodes, f"new-{op}") for op in task.operators]
    return collect_stages(spec, task, sets, resolve)


def _training_of(stage: Stage) -> dict[str, Any]:
    """What a train stage trains, seeds aside: its training config (resolved configs), else its
    raw config without the seeds and what it is called (``method``, ``operator``)."""
    train = stage.config.get("train")
    if isinstance(train, Mapping):
        return {k: v for k, v in train.items() if k != "seeds"}
    return {k: v for k, v in stage.config.items() if k not in ("seeds", "method", "operator")}


def _cell_stages(
    spec: PipelineSpec, task: TaskSpec, model: str, needs_scores: bool, resolve: ConfigResolver
) -> list[Stage]:
    c = Cell(spec, task, model, resolve)
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
    scorer = base
    if spec.scorer is not None:
        own = scorer_stage(c)
        if _training_of(own) != _training_of(base):  # else the base policy is that scorer
            scorer = own
            stages.append(scorer)
    contrast, fit = threshold_stages(spec, task, model, scorer.id, resolve)
    stages += [contrast, fit]
    map_inputs = {"thresholds": fit.id, "scores:contrast": contrast.id}
    scores: dict[str, Stage] = {}
    for op in task.operators:
        score = scores[op] = Stage(
            id=f"score/{c.cell}/{op}",
            kind="score",
            output=f"scores/{c.cell}/new-{op}",
            config=resolve("score", {**score_raw, "set": op}),
            inputs={"policy": scorer.id, "demos0": c.new(op), "thresholds": fit.id},
            label=f"score {c.t} {model} D_new of {op}",
        )
        stages.append(score)
        map_inputs[f"scores:{op}"] = score.id
        demo_score = None
        if any(m.startswith("demo-score") for m in spec.methods):
            demo_score = demo_score_stage(c, op, naive[op])
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
        stages += sensitivity_stages(c, scores, fit)
    return stages
