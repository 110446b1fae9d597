"""The study report's tables, from :class:`~elicit_jax.pipeline.elicitation.gather.StudyData`:
the paper's Table 2, per person, demonstration lengths, learning by attempt, the interface
ablation, HG-DAgger, the M-filter's counts and the thresholds. How a condition's success and
the differences between conditions are computed: :mod:`~elicit_jax.pipeline.elicitation.success`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from elicit_jax.compat.thresholds import pair_from_json
from elicit_jax.pipeline.elicitation.gather import DISTANCE_KEY, SessionData, StudyData
from elicit_jax.pipeline.elicitation.success import (
    CONDITION_LABELS,
    DIFFERENCES,
    cells_of,
    compare,
    diff_text,
    people_of,
    population_by_seed,
    study_differences,
    success_cells,
)
from elicit_jax.pipeline.tables import Table, mean_std
from elicit_jax.stats import holm_over, tested

TABLE2 = ("base", "naive", "filtered", "informed")
ARMS = ("naive", "rejection", "prompt", "indicator", "feedback", "informed")
AS_BASE = 0.01
"""Largest mean squared action difference (per dimension, imagined on D_base's states) at which
a person's final choices count as acting as the base operator's."""
CURVE_ATTEMPTS = 10
"""Demonstration attempts shown in the learning-curve table."""


def table2(data: StudyData) -> Table:
    """The paper's Table 2 layout: per task, Base / Naive / Naive + M-filtered / Informed."""
    cells = success_cells(data)
    header = ["task", "model", *[CONDITION_LABELS[c] for c in TABLE2]]
    header += [f"{CONDITION_LABELS[a]} − {CONDITION_LABELS[b]}" for a, b in DIFFERENCES]
    header += ["people"]
    rows = []
    family = iter(study_differences(data))
    for task, model in cells_of(data):
        people = people_of(data, task, model)
        row = [task, model]
        for cond in TABLE2:
            row.append(
                mean_std(list(population_by_seed(cells, task, model, cond, people).values()))
            )
        for _ in DIFFERENCES:
            *_, diff, adjusted = next(family)
            row.append(diff_text(diff, adjusted))
        row.append(str(len(people)))
        rows.append(row)
    return header, rows


def table2_tests(data: StudyData) -> int:
    """How many of Table 2's differences are tests (the m of its Holm adjustment)."""
    return tested([d.p for *_, d, _ in study_differences(data) if d is not None])


def _traits(record: Mapping[str, Any]) -> str:
    t = record.get("traits", {})
    keys = (("imitation", "im"), ("uptake", "up"), ("explore", "ex"), ("noise", "noise"))
    keys += (("practice", "pr"), ("speed", "sp"), ("gain", "gain"), ("delay", "delay"))
    keys += (("memory", "mem"), ("reach", "reach"))
    return " ".join(f"{short} {t[k]:g}" for k, short in keys if k in t)


def _distances(any_session: SessionData | None, informed: SessionData | None) -> str:
    """``start → end`` of the person's θ's distance from the base operator's (the start is
    the same in every session of a person; the end is the informed session's)."""
    start = (any_session.person_record.get(DISTANCE_KEY) or {}) if any_session else {}
    end = (informed.person_record.get(DISTANCE_KEY) or {}) if informed else {}
    first = f"{start['start']:.2f}" if "start" in start else "–"
    return f"{first} → {end['end']:.2f}" if "end" in end else first


def _changes(record: Mapping[str, Any]) -> str:
    """The operator choices whose value differs between the start and the end of a session."""
    start, final = record.get("start_choices", {}), record.get("choices", {})
    keys = [k for k in {**start, **final} if _value(start.get(k, "–")) != _value(final.get(k, "–"))]
    return ", ".join(f"{k}→{_value(final.get(k, '–'))}" for k in keys) or "none"


def _value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.3g}"
    if isinstance(v, list):
        return "(" + ",".join(_value(x) for x in v) + ")"
    return str(v)


def acts_as_base(data: StudyData, task: str, choices: Mapping[str, Any]) -> bool | None:
    """Whether a person with ``choices`` acts as the base operator's style does: both imagined
    (noise-free, the base's motor parameters, the people's loose watching tolerances, so a
    wrist a few degrees off does not stall the comparison) along D_base's first states give
    actions within :data:`AS_BASE` (mean squared difference per dimension). The report's
    check, never a person's: it reads the base style. None when D_base or the base style is
    not available."""
    from elicit_jax.elicit.people.imagine import action_error, imagine
    from elicit_jax.elicit.people.learn import watching
    from elicit_jax.errors import ElicitError
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.operators import style_of

    states = data.base_states.get(task)
    if not states:
        return None
    try:
        base = style_of(task, "base")
    except ElicitError:
        return None
    key = (task, repr(sorted((k, repr(v)) for k, v in choices.items())))
    if key not in _ACTS_AS_BASE:
        sim = make_task(task)
        own = {k: tuple(v) if isinstance(v, list) else v for k, v in choices.items()}
        mine = imagine(sim, watching(base, own), list(states))
        theirs = imagine(sim, watching(base, dict(base.choices)), list(states))
        _ACTS_AS_BASE[key] = action_error(mine, theirs) < AS_BASE
    return _ACTS_AS_BASE[key]


_ACTS_AS_BASE: dict[tuple[str, str], bool] = {}


def person_table(data: StudyData, task: str, model: str) -> Table:
    """Per person: starting style, traits, success per condition, what the informed session
    changed and whether it ends acting as the base operator's style does."""
    cells = success_cells(data)
    conds = [
        c for c in CONDITION_LABELS if c != "base" and any(k[:3] == (task, model, c) for k in cells)
    ]
    by = {(s.condition, s.person): s for s in data.sessions if (s.task, s.model) == (task, model)}
    measured = any(DISTANCE_KEY in s.person_record for s in by.values())
    header = ["person", "starts as", "traits"]
    header += ["θ from base: start → informed end"] if measured else []
    header += [CONDITION_LABELS[c] for c in conds]
    header += ["informed: accepted / episodes", "informed: choices changed", "ends as base"]
    rows = []
    for p in people_of(data, task, model):
        any_session = next((s for (c, q), s in by.items() if q == p), None)
        row = [p, any_session.style if any_session else "?"]
        row.append(_traits(any_session.person_record) if any_session else "")
        if measured:
            row.append(_distances(any_session, by.get(("informed", p))))
        for cond in conds:
            row.append(mean_std(list(cells.get((task, model, cond, p), {}).values())))
        informed = by.get(("informed", p))
        if informed is not None:
            demos = informed.demonstrations
            row.append(f"{len(informed.accepted)} / {len(demos)}")
            row.append(_changes(informed.person_record))
            match = acts_as_base(data, task, informed.person_record.get("choices", {}))
            row.append("–" if match is None else "yes" if match else "no")
        else:
            row += ["–", "–", "–"]
        rows.append(row)
    return header, rows


def _conditions(data: StudyData, task: str, model: str) -> list[str]:
    present = {s.condition for s in data.sessions if (s.task, s.model) == (task, model)}
    return [c for c in CONDITION_LABELS if c in present]


def _sessions(data: StudyData, task: str, model: str, cond: str) -> list[SessionData]:
    return [s for s in data.sessions if (s.task, s.model, s.condition) == (task, model, cond)]


def length_table(data: StudyData) -> Table:
    """Mean length of the accepted demonstrations per condition, against D_base's."""
    header = ["task", "model", "demonstrations", "n", "mean length (std)", "vs base"]
    rows = []
    for task, model in cells_of(data):
        base = data.base_lengths.get(task)
        if base:
            rows.append([task, model, "D_base", str(base[2]), f"{base[0]:.1f} ({base[1]:.1f})", ""])
        for cond in _conditions(data, task, model):
            key = "operator_steps" if cond.endswith("dagger") else "length"
            lens = [float(r[key]) for s in _sessions(data, task, model, cond) for r in s.accepted]
            if not lens:
                continue
            comparable = base and key == "length"  # DAgger: interventions, not whole demos
            vs = f"{100 * (np.mean(lens) / base[0] - 1):+.1f}%" if comparable else "–"
            label = CONDITION_LABELS[cond] + (" (operator steps)" if key != "length" else "")
            rows.append(
                [
                    task,
                    model,
                    label,
                    str(len(lens)),
                    f"{np.mean(lens):.1f} ({np.std(lens, ddof=1) if len(lens) > 1 else 0.0:.1f})",
                    vs,
                ]
            )
    return header, rows


def learning_curves(data: StudyData, task: str, model: str) -> dict[str, np.ndarray]:
    """Per condition: (attempts, 3) rows of [mean incompatible fraction, rule accept rate,
    people] over the population, by demonstration attempt (1st, 2nd, ...)."""
    out = {}
    for cond in _conditions(data, task, model):
        per: dict[int, list[tuple[float, bool]]] = {}
        for s in _sessions(data, task, model, cond):
            demos = [r for r in s.demonstrations if r["fraction_incompatible"] is not None]
            for k, r in enumerate(demos):
                per.setdefault(k, []).append(
                    (float(r["fraction_incompatible"]), r["rule_verdict"] == "accept")
                )
        if per:
            out[cond] = np.array(
                [
                    [np.mean([f for f, _ in v]), np.mean([a for _, a in v]), len(v)]
                    for _, v in sorted(per.items())
                ]
            )
    return out


def learning_table(data: StudyData, task: str, model: str) -> Table:
    """Incompatible fraction and the rule's accept rate by demonstration attempt, mean over
    the population (naive sessions: what the rule would have said)."""
    curves = learning_curves(data, task, model)
    k = min(CURVE_ATTEMPTS, max((len(c) for c in curves.values()), default=0))
    header = ["condition", "", *[f"#{i + 1}" for i in range(k)], "episodes per accepted demo"]
    rows = []
    for cond, curve in curves.items():
        cells = [f"{100 * v:.0f}%" for v in curve[:k, 0]] + [""] * (k - min(k, len(curve)))
        accept = [f"{100 * v:.0f}%" for v in curve[:k, 1]] + [""] * (k - min(k, len(curve)))
        sessions = _sessions(data, task, model, cond)
        demos = sum(len(s.demonstrations) for s in sessions)
        accepted = sum(len(s.accepted) for s in sessions)
        per = f"{demos / accepted:.1f}" if accepted else "–"
        rows.append([CONDITION_LABELS[cond], "incompatible", *cells, per])
        rows.append(["", "rule accepts", *accept, ""])
    return header, rows


def ablation_table(data: StudyData, task: str, model: str) -> Table:
    """Which part of the interface does the work: nothing (naive), each part alone, all three."""
    cells = success_cells(data)
    people = people_of(data, task, model)
    header = ["shown", "success %", "vs Naive", "rule accepts", "incompatible"]
    header += ["demos per accepted", "people who changed", "ends as base"]
    rows = []
    arms, vs_naive = _ablation_diffs(data, task, model)
    for cond, diff, adjusted in zip(arms, vs_naive, holm_over(vs_naive), strict=True):
        sessions = _sessions(data, task, model, cond)
        demos = [r for s in sessions for r in s.demonstrations if r["rule_verdict"]]
        frac = [float(r["fraction_incompatible"]) for r in demos]
        accepted = sum(len(s.accepted) for s in sessions)
        changed = sum(1 for s in sessions if _changes(s.person_record) != "none")
        ends = [acts_as_base(data, task, s.person_record.get("choices", {})) for s in sessions]
        rows.append(
            [
                CONDITION_LABELS[cond] if cond != "informed" else "All three (informed)",
                mean_std(list(population_by_seed(cells, task, model, cond, people).values())),
                "" if cond == "naive" else diff_text(diff, adjusted),
                f"{100 * np.mean([r['rule_verdict'] == 'accept' for r in demos]):.0f}%"
                if demos
                else "–",
                f"{100 * np.mean(frac):.1f}%" if frac else "–",
                f"{len(demos) / accepted:.1f}" if accepted else "–",
                f"{changed}/{len(sessions)}",
                "–" if None in ends else f"{sum(ends)}/{len(sessions)}",
            ]
        )
    return header, rows


def _ablation_diffs(data: StudyData, task: str, model: str) -> tuple[list[str], list]:
    cells = success_cells(data)
    arms = [c for c in ARMS if _sessions(data, task, model, c)]
    return arms, [None if c == "naive" else compare(cells, task, model, c, "naive") for c in arms]


def ablation_tests(data: StudyData, task: str, model: str) -> int:
    """How many of the ablation's differences from Naive are tests (its Holm family's m)."""
    return tested([d.p for d in _ablation_diffs(data, task, model)[1] if d is not None])


def dagger_table(data: StudyData) -> Table:
    """HG-DAgger sessions: success, how much of each episode the person controlled, how often
    it took over."""
    cells = success_cells(data)
    header = ["task", "model", "condition", "success %", "intervention rate"]
    header += ["interventions per episode", "accepted demos", "operator steps per accepted"]
    rows = []
    for task, model in cells_of(data):
        people = people_of(data, task, model)
        for cond in ("naive-dagger", "informed-dagger"):
            sessions = _sessions(data, task, model, cond)
            if not sessions:
                continue
            demos = [r for s in sessions for r in s.demonstrations]
            rates = [r["intervention_rate"] for r in demos if r["intervention_rate"] is not None]
            takes = [r["interventions"] or 0 for r in demos]
            acc = [r for s in sessions for r in s.accepted]
            rows.append(
                [
                    task,
                    model,
                    CONDITION_LABELS[cond],
                    mean_std(list(population_by_seed(cells, task, model, cond, people).values())),
                    f"{100 * np.mean(rates):.0f}%" if rates else "–",
                    f"{np.mean(takes):.1f}" if takes else "–",
                    str(len(acc)),
                    f"{np.mean([r['operator_steps'] for r in acc]):.1f}" if acc else "–",
                ]
            )
    return header, rows


def filter_table(data: StudyData) -> Table:
    """What the M-filter kept of each naive session."""
    header = ["task", "model", "person", "pairs kept", "demos with pairs kept"]
    rows = [
        [
            f.task,
            f.model,
            f.person,
            f"{f.pairs_kept}/{f.pairs_total}"
            + (f" ({100 * f.pairs_kept / f.pairs_total:.1f}%)" if f.pairs_total else ""),
            f"{f.episodes_kept}/{f.episodes_total}",
        ]
        for f in data.filters
    ]
    return header, rows


def threshold_table(data: StudyData) -> Table:
    """The thresholds every session and the M-filter used."""
    from elicit_jax.pipeline.tables import trust_text

    header = ["task", "model", "λ", "η", "how", "balanced acc.", "trust"]
    rows = [
        [
            task,
            model,
            *(f"{v:.4g}" for v in pair_from_json(t)),
            "fitted on contrast sets" if t["method"] == "fit" else "set by hand",
            "–" if t.get("balanced_accuracy") is None else f"{t['balanced_accuracy']:.3g}",
            trust_text(t.get("trust")),
        ]
        for (task, model), t in data.thresholds.items()
    ]
    return header, rows
