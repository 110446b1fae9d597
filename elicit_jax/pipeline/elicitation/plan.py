"""Expand an elicitation study into its stage graph.

Per task: collect D_base and the two contrast sets. Per task × model: train the base policy
(all seeds at once) and evaluate it; score the contrast sets with the first seed's base policy
and fit (λ, η). Per person of the task's population, one session per condition — ``naive``
(practice only), ``rejection`` (the rule applied, nothing shown: filtering without
teaching), ``informed`` (prompt + live indicator + feedback), each ablation arm
(``prompt``, ``indicator`` or ``feedback`` only) and, on a DAgger task, ``naive-dagger`` and
``informed-dagger`` — all against the first seed's base policy and the fitted thresholds, all
from the same session seed (the person meets the same initial states in every condition);
then train on D_base ∪ the session's accepted demonstrations (all seeds) and evaluate. The
``filtered`` condition scores the naive session's demonstrations and drops the incompatible
pairs before training. One report.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from elicit_jax.pipeline.elicitation.gather import STUDY_REPORT_STAGE
from elicit_jax.pipeline.elicitation.spec import StudySpec, StudyTask
from elicit_jax.pipeline.elicitation.stages import ELICITATION_KINDS
from elicit_jax.pipeline.graph import Graph, Stage
from elicit_jax.pipeline.plan import (
    collect_stages,
    contrast_sets,
    report_stage,
    threshold_stages,
    unresolved,
)
from elicit_jax.pipeline.plan_cell import ConfigResolver
from elicit_jax.pipeline.stage_kind import reported_kinds
from elicit_jax.pipeline.stages import FILTERING_KINDS

SESSION_SEED_STRIDE = 1000
REPORTED = reported_kinds((*FILTERING_KINDS, *ELICITATION_KINDS))
"""The stage kinds the study's report stage reads
(:attr:`~elicit_jax.pipeline.stage_kind.StageKind.reported`)."""


def session_modes(spec: StudySpec, task: StudyTask) -> dict[str, dict[str, Any]]:
    """Session condition -> its mode, parts shown and DAgger flag, for one task."""
    out: dict[str, dict[str, Any]] = {}
    if {"naive", "filtered"} & set(spec.conditions):
        out["naive"] = {"mode": "naive", "show": [], "dagger": False}
    if "rejection" in spec.conditions:
        out["rejection"] = {"mode": "informed", "show": []}
    if "informed" in spec.conditions:
        out["informed"] = {"mode": "informed", "show": ["prompt", "indicator", "feedback"]}
    for arm in spec.ablation:
        out[arm] = {"mode": "informed", "show": [arm]}
    if task.dagger:
        for cond in spec.dagger_conditions:
            show = [] if cond == "naive" else ["prompt", "indicator", "feedback"]
            out[f"{cond}-dagger"] = {"mode": cond, "show": show, "dagger": True}
    for mode in out.values():
        mode.setdefault("dagger", False)
    return out


def session_seed(spec: StudySpec, person: int) -> int:
    """Session seed of person ``person``: every condition of a person shares it."""
    return spec.collect_seed * SESSION_SEED_STRIDE + person


def person_id(index: int) -> str:
    return f"p{index}"


def build_study_graph(spec: StudySpec, resolve: ConfigResolver = unresolved) -> Graph:
    """The stage graph of an elicitation study (see the module docstring)."""
    stages: list[Stage] = []
    for task in spec.tasks:
        stages += _collect_stages(spec, task, resolve)
        for model in spec.models:
            stages += _cell_stages(spec, task, model, resolve)
    stages.append(report_stage(spec, STUDY_REPORT_STAGE, stages, REPORTED, resolve))
    return Graph(stages)


def _collect_stages(spec: StudySpec, task: StudyTask, resolve: ConfigResolver) -> list[Stage]:
    base = ("base", task.base_operator, task.base_episodes, "base")
    return collect_stages(
        spec, task, [base, *contrast_sets(task, ("holdout", "incompatible"))], resolve
    )


@dataclasses.dataclass(frozen=True)
class _Cell:
    """One task × model cell of the study: what its stages share."""

    spec: StudySpec
    task: StudyTask
    model: str
    resolve: ConfigResolver

    @property
    def name(self) -> str:
        return f"{self.task.name}/{self.model}"

    @property
    def where(self) -> dict[str, str]:
        return {"task": self.task.name, "model": self.model}

    @property
    def base_data(self) -> str:
        return f"collect/{self.task.name}/base"

    def policy_stage(
        self, kind: str, suffix: str, output: str, inputs: dict[str, str], method: str, who: Any
    ) -> Stage:
        """A ``train`` or ``evaluate`` stage (all seeds) of one training set."""
        spec = self.spec
        raw = {**spec.section(kind), **self.where, "seeds": list(spec.seeds)}
        raw |= {"profile": spec.profile}
        return Stage(
            id=f"{kind}/{self.name}/{suffix}",
            kind=kind,
            output=output,
            config=self.resolve(kind, {**raw, "method": method, "operator": who}),
            inputs=inputs,
            label=f"{kind} {self.task.name} {self.model} {suffix}",
        )

    def train(self, method: str, who: str | None, extra: dict[str, str]) -> list[Stage]:
        """Train on D_base plus ``extra`` (all seeds), and evaluate every seed."""
        suffix = method if who is None else f"{method}/{who}"
        flat = f"{self.name}/{suffix.replace('/', '-')}"
        inputs = {"demos0": self.base_data, **extra}
        tr = self.policy_stage("train", suffix, f"policies/{flat}", inputs, method, who)
        ev = self.policy_stage(
            "evaluate", suffix, f"evals/{flat}.parquet", {"policy": tr.id}, method, who
        )
        return [tr, ev]


def _cell_stages(
    spec: StudySpec, task: StudyTask, model: str, resolve: ConfigResolver
) -> list[Stage]:
    c = _Cell(spec, task, model, resolve)
    stages = c.train("base", None, {})
    contrast, fit = threshold_stages(spec, task, model, stages[0].id, resolve)
    stages += [contrast, fit]
    for index, person in enumerate(task.people):
        stages += _person_stages(c, index, person, stages[0], fit)
    return stages


def _person_stages(c: _Cell, index: int, person: str, base: Stage, fit: Stage) -> list[Stage]:
    """One person's sessions (one per condition), each retrained on, and the M-filter of
    their naive session."""
    spec, t, who = c.spec, c.task.name, person_id(index)
    stages: list[Stage] = []
    sessions = {}
    for cond, mode in session_modes(spec, c.task).items():
        raw = {**_score_options(spec), **spec.section("session"), **c.where, **mode}
        raw |= {"operator": person, "person": who, "condition": cond}
        raw |= {"seed": session_seed(spec, index), "policy_seed": spec.seeds[0]}
        sessions[cond] = Stage(
            id=f"session/{c.name}/{cond}/{who}",
            kind="session",
            output=f"sessions/{c.name}/{cond}/{who}",
            config=c.resolve("session", raw),
            inputs={"policy": base.id, "base": c.base_data, "thresholds": fit.id},
            label=f"session {t} {cond} {who} ({person.partition(',')[0]})",
        )
        stages.append(sessions[cond])
        if cond != "naive" or "naive" in spec.conditions:
            stages += c.train(cond, who, {"demos1": sessions[cond].id})
    if "filtered" in spec.conditions:
        raw = {"score": spec.section("score"), "filter": spec.section("filter")}
        filt = Stage(
            id=f"filter-session/{c.name}/{who}",
            kind="filter-session",
            output=f"filtered/{c.name}/{who}",
            config=c.resolve(
                "filter-session", {**raw, **c.where, "person": who, "policy_seed": spec.seeds[0]}
            ),
            inputs={"session": sessions["naive"].id, "policy": base.id, "thresholds": fit.id},
            label=f"M-filter {t} naive {who}",
        )
        stages += [filt, *c.train("filtered", who, {"demos1": filt.id})]
    return stages


def _score_options(spec: StudySpec) -> dict[str, Any]:
    """The scoring conventions of ``[score]`` a session's live scorer shares."""
    score = spec.section("score")
    return {k: score[k] for k in ("likelihood", "ddof") if k in score}
