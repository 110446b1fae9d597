"""Report content: the data a report shows and the tables built from it.

:class:`ReportData` holds everything a report shows (gathered from a run directory by
:mod:`elicit_jax.pipeline.gather`); the ``*_table`` functions turn it into ``(header, rows)``
tables in the paper's layout, which :mod:`elicit_jax.pipeline.report` renders.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

METHOD_LABELS = {
    "base": "Base",
    "naive": "Naive",
    "filtered": "M-Filtered",
    "filtered-episode": "M-Filtered (episodes)",
    "random": "Random filter",
    "longest": "Drop longest",
    "shortest": "Drop shortest",
    "likelihood": "Likelihood-only",
    "novelty": "Novelty-only",
}


@dataclasses.dataclass(frozen=True)
class ResultRow:
    """Success of one trained policy (one seed), at its selected checkpoint."""

    task: str
    model: str
    method: str
    operator: str | None
    seed: int
    success: float
    mean_length: float
    n_rollouts: int
    checkpoint: str


@dataclasses.dataclass(frozen=True)
class ThresholdRow:
    """A threshold fit and the contrast sets it was fitted on."""

    task: str
    model: str
    lambda_: float
    eta: float
    compatible: str
    incompatible: str
    metrics: Mapping[str, Any]


@dataclasses.dataclass(frozen=True)
class LengthRow:
    """Demonstration lengths of one demo set."""

    task: str
    name: str
    operator: str
    n_episodes: int
    mean_length: float
    std_length: float


@dataclasses.dataclass(frozen=True)
class FilterRow:
    """What one filter kept of one D_new."""

    task: str
    model: str
    method: str
    operator: str
    pairs_kept: int
    pairs_total: int
    episodes_kept: int
    episodes_total: int


@dataclasses.dataclass(frozen=True)
class ReportData:
    """Everything a report shows."""

    pipeline: str
    profile: str
    description: str
    run_dir: str
    spec_text: str
    results: tuple[ResultRow, ...]
    thresholds: tuple[ThresholdRow, ...] = ()
    lengths: tuple[LengthRow, ...] = ()
    filters: tuple[FilterRow, ...] = ()
    maps: tuple[tuple[str, str], ...] = ()
    configs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    versions: Mapping[str, str] = dataclasses.field(default_factory=dict)
    notes: tuple[str, ...] = ()


Table = tuple[list[str], list[list[str]]]


def mean_std(values: Sequence[float], scale: float = 100.0) -> str:
    """``mean (std)`` of ``values × scale``, one decimal; population std over seeds (ddof = 0,
    as numpy and ``elicit-jax evaluate``).

    One value gives ``mean (–)``: a single seed has no spread.
    """
    arr = np.asarray(values, dtype=float) * scale
    if arr.size == 0:
        return "–"
    if arr.size == 1:
        return f"{arr[0]:.1f} (–)"
    return f"{arr.mean():.1f} ({arr.std():.1f})"


def _cells(results: Sequence[ResultRow]) -> dict[tuple, list[float]]:
    out: dict[tuple, list[float]] = {}
    for r in sorted(results, key=lambda r: r.seed):
        out.setdefault((r.task, r.model, r.method, r.operator), []).append(r.success)
    return out


def results_tables(data: ReportData) -> list[tuple[str, Table]]:
    """One table per task × model in the paper's layout: rows = operators, columns = methods.

    The first row is the base policy (D_base only); each operator row gives π_new trained on
    D_base ∪ D_new (Naive) and on the filtered D_new (M-Filtered, baselines), as success
    rate % mean (std) over seeds.
    """
    cells = _cells(data.results)
    out = []
    for task, model in dict.fromkeys((r.task, r.model) for r in data.results):
        methods = [
            m
            for m in METHOD_LABELS
            if m != "base" and (task, model, m) in {(k[0], k[1], k[2]) for k in cells}
        ]
        ops = list(
            dict.fromkeys(k[3] for k in cells if k[:2] == (task, model) and k[3] is not None)
        )
        header = ["operator", *[METHOD_LABELS[m] for m in methods]]
        base = mean_std(cells.get((task, model, "base", None), []))
        rows = [[f"base only: {base}", *["" for _ in methods]]]
        for op in ops:
            rows.append([op, *[mean_std(cells.get((task, model, m, op), [])) for m in methods]])
        out.append(
            (
                f"{task} — {model}: success % (best checkpoint per seed), mean (std) over seeds",
                (header, rows),
            )
        )
    return out


def models_table(data: ReportData) -> list[tuple[str, Table]]:
    """Per task with several models: rows = base + operators, columns = models (Naive)."""
    cells = _cells(data.results)
    out = []
    for task in dict.fromkeys(r.task for r in data.results):
        models = list(dict.fromkeys(r.model for r in data.results if r.task == task))
        if len(models) < 2:
            continue
        ops = list(
            dict.fromkeys(
                r.operator for r in data.results if r.task == task and r.method == "naive"
            )
        )
        rows = [
            [
                "Base (D_base only)",
                *[mean_std(cells.get((task, m, "base", None), [])) for m in models],
            ]
        ]
        for op in ops:
            rows.append(
                [
                    f"Naive + {op}",
                    *[mean_std(cells.get((task, m, "naive", op), [])) for m in models],
                ]
            )
        out.append((f"{task}: model comparison, success % mean (std)", (["", *models], rows)))
    return out


def threshold_table(data: ReportData) -> Table:
    """λ, η, fit quality and the contrast sets each fit used."""
    header = [
        "task",
        "model",
        "λ",
        "η",
        "balanced acc.",
        "margin",
        "leave-one-out acc.",
        "trust",
        "compatible set",
        "incompatible set",
    ]
    rows = []
    for t in data.thresholds:
        m = t.metrics
        rows.append(
            [
                t.task,
                t.model,
                f"{t.lambda_:.4g}",
                f"{t.eta:.4g}",
                _num(m.get("balanced_accuracy")),
                _num(m.get("margin")),
                _num(m.get("loo_accuracy")),
                trust_text(m.get("trust")),
                t.compatible,
                t.incompatible,
            ]
        )
    return header, rows


def trust_text(trust: Mapping[str, Any] | None) -> str:
    """A fit's trust verdict for a report cell: ``ok``, or the verdict and its reasons."""
    if not trust:
        return "–"
    if trust.get("trustworthy"):
        return "ok"
    verdict = "MEANINGLESS (forced)" if trust.get("meaningless") else "NOT TRUSTWORTHY"
    return f"{verdict}: " + "; ".join(trust.get("problems", []))


def decisions_table(data: ReportData) -> Table:
    """Per fit and contrast operator: incompatible pairs and rejected demos under (λ, η)."""
    header = ["task", "model", "operator", "pairs", "incompatible pairs", "demos rejected"]
    rows = []
    for t in data.thresholds:
        for op, c in dict(t.metrics.get("per_operator", {})).items():
            rows.append(
                [
                    t.task,
                    t.model,
                    op,
                    str(c["pairs"]),
                    f"{c['incompatible_pairs']} ({_pct(c['incompatible_pairs'], c['pairs'])})",
                    f"{c['rejected_episodes']}/{c['episodes']}",
                ]
            )
    return header, rows


def filter_table(data: ReportData) -> Table:
    """Fraction of each D_new that each filter kept."""
    header = ["task", "model", "operator", "filter", "pairs kept", "episodes kept"]
    rows = [
        [
            f.task,
            f.model,
            f.operator,
            METHOD_LABELS.get(f.method, f.method),
            f"{f.pairs_kept}/{f.pairs_total} ({_pct(f.pairs_kept, f.pairs_total)})",
            f"{f.episodes_kept}/{f.episodes_total}",
        ]
        for f in data.filters
    ]
    return header, rows


def length_table(data: ReportData) -> Table:
    """Mean demonstration length per operator (steps), with std over episodes."""
    header = ["task", "demo set", "operator", "episodes", "mean length (std)"]
    rows = [
        [r.task, r.name, r.operator, str(r.n_episodes), f"{r.mean_length:.1f} ({r.std_length:.1f})"]
        for r in data.lengths
    ]
    return header, rows


def rollout_length_table(data: ReportData) -> Table:
    """Mean rollout length (steps, until success or the horizon) per policy over seeds, and
    the checkpoint selected for each seed."""
    groups: dict[tuple, list[ResultRow]] = {}
    for r in sorted(data.results, key=lambda r: (r.task, r.model, r.operator or "", r.seed)):
        groups.setdefault((r.task, r.model, r.method, r.operator), []).append(r)
    header = [
        "task",
        "model",
        "operator",
        "training set",
        "mean rollout length",
        "selected checkpoint per seed",
    ]
    rows = [
        [
            t,
            m,
            op or "–",
            METHOD_LABELS.get(meth, meth),
            f"{np.mean([r.mean_length for r in rs]):.1f}",
            ", ".join(f"s{r.seed}: {r.checkpoint}" for r in rs),
        ]
        for (t, m, meth, op), rs in groups.items()
    ]
    return header, rows


def _num(v: Any) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    return f"{v:.3g}" if isinstance(v, float) else str(v)


def _pct(a: int, b: int) -> str:
    return f"{100.0 * a / b:.1f}%" if b else "–"
