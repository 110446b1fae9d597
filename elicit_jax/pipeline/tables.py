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

from elicit_jax.pipeline.findings import Findings
from elicit_jax.stats import PairedDiff, format_diff, paired_t_interval

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
    "filtered-valley": "M-Filtered (valley λ)",
    "deminf": "DemInf",
    "deminf-matched": "DemInf (M's amount)",
    "demo-score": "Demo-SCORE",
    "demo-score-matched": "Demo-SCORE (M's amount)",
    "cupid": "CUPID",
    "cupid-matched": "CUPID (M's amount)",
    "quality": "Quality flags",
    "quality-matched": "Quality flags (M's amount)",
}
INTERVAL_NOTE = (
    "95% interval of the difference, paired by training seed and initial states (every policy "
    "is evaluated on the same seeded initial states): Student's t over the per-seed differences "
    "(see docs/pipelines.md); * marks an interval that excludes 0."
)


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
    init_states: str = ""
    study: str = "main"
    point: int | None = None
    selection: str = "reported"
    eval_seeds: tuple[int, ...] = ()
    select_success: float | None = None


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
    note: str = ""


@dataclasses.dataclass(frozen=True)
class CurationRow:
    """Per-demonstration scores of one curation baseline on one D_new."""

    task: str
    model: str | None
    method: str
    operator: str
    scores: tuple[float, ...]
    threshold: float | None
    trusted: bool
    report: Mapping[str, Any]


@dataclasses.dataclass(frozen=True)
class LambdaPoint:
    """One λ of the sensitivity study: point k of the fit's margin range."""

    task: str
    model: str
    point: int
    lambda_: float
    fitted: float
    low: float
    high: float


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
    curation: tuple[CurationRow, ...] = ()
    heldout: tuple[ResultRow, ...] = ()
    lambda_points: tuple[LambdaPoint, ...] = ()
    maps: tuple[tuple[str, str], ...] = ()
    figures: tuple[tuple[str, str], ...] = ()
    configs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    versions: Mapping[str, str] = dataclasses.field(default_factory=dict)
    notes: tuple[str, ...] = ()
    findings: Findings | None = None
    provenance: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    raw_results: bool = False


Table = tuple[list[str], list[list[str]]]


STD_NOTE = (
    "Every std in these tables is the sample standard deviation (ddof = 1), the same "
    "convention as the intervals; a single value shows no spread (–)."
)


def mean_std(values: Sequence[float], scale: float = 100.0) -> str:
    """``mean (std)`` of ``values × scale``, one decimal; sample std over seeds (ddof = 1, as
    the intervals beside it, :data:`STD_NOTE`).

    One value gives ``mean (–)``: a single seed has no spread.
    """
    arr = np.asarray(values, dtype=float) * scale
    if arr.size == 0:
        return "–"
    if arr.size == 1:
        return f"{arr[0]:.1f} (–)"
    return f"{arr.mean():.1f} ({arr.std(ddof=1):.1f})"


def selection_label(results: Sequence[ResultRow]) -> str:
    """How the tables' checkpoints were chosen, in a few words for a table title."""
    rules = {r.selection for r in results}
    if rules == {"heldout"}:
        return "checkpoint per seed chosen on held-out rollouts"
    if rules == {"reported"}:
        return "best checkpoint per seed on the reported rollouts: biased upwards"
    return "checkpoint per seed: mixed selection rules, see above"


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
                f"{task} — {model}: success % ({selection_label(data.results)}), "
                "mean (std) over seeds",
                (header, rows),
            )
        )
    return out


def paired_diff(a: Sequence[ResultRow], b: Sequence[ResultRow]) -> PairedDiff | None:
    """Paired interval of success(a) − success(b) over the seeds both have; None when there is
    no common seed or a pair was evaluated on different initial states (not comparable)."""
    by_seed = {r.seed: r for r in b}
    pairs = [(r, by_seed[r.seed]) for r in sorted(a, key=lambda r: r.seed) if r.seed in by_seed]
    if not pairs or any(x.init_states != y.init_states for x, y in pairs):
        return None
    return paired_t_interval([x.success for x, _ in pairs], [y.success for _, y in pairs])


def _rows(results: Sequence[ResultRow]) -> dict[tuple, list[ResultRow]]:
    out: dict[tuple, list[ResultRow]] = {}
    for r in results:
        out.setdefault((r.task, r.model, r.method, r.operator), []).append(r)
    return out


FROM_BASE = ("filtered", "filtered-episode", "filtered-valley")


def difference_tables(data: ReportData) -> list[tuple[str, Table]]:
    """Beside each results table: every cell's difference from Naive with its paired 95%
    interval (the Naive column: Naive − Base, does adding this operator's data help?), then
    the M-filters' differences from Base (the paper's claim: filtered ≥ base)."""
    rows_of = _rows(data.results)
    out = []
    for task, model in dict.fromkeys((r.task, r.model) for r in data.results):
        methods = [
            m
            for m in METHOD_LABELS
            if m != "base" and any(k[:3] == (task, model, m) for k in rows_of)
        ]
        ops = list(
            dict.fromkeys(k[3] for k in rows_of if k[:2] == (task, model) and k[3] is not None)
        )
        base = rows_of.get((task, model, "base", None), [])
        columns = [(m, "base" if m == "naive" else "naive") for m in methods]
        columns += [(m, "base") for m in FROM_BASE if m in methods and base]
        rows = []
        for op in ops:
            refs = {"base": base, "naive": rows_of.get((task, model, "naive", op), [])}
            cells = []
            for m, ref in columns:
                mine = rows_of.get((task, model, m, op), [])
                cells.append(
                    format_diff(paired_diff(mine, refs[ref])) if mine and refs[ref] else "–"
                )
            rows.append([op, *cells])
        header = ["operator", *[f"{METHOD_LABELS[m]} − {METHOD_LABELS[r]}" for m, r in columns]]
        what = "difference from Naive" if any(r == "naive" for _, r in columns) else "Naive − Base"
        if any(r == "base" and m != "naive" for m, r in columns):
            what += " (M-filters also from Base)"
        out.append((f"{task} — {model}: {what}, points (paired 95% interval)", (header, rows)))
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


def curation_table(data: ReportData) -> Table:
    """What each curation baseline saw: its per-demo scores, its own cut, its diagnostics."""
    from elicit_jax.curation.demo_score import at_chance

    header = [
        "task",
        "model",
        "operator",
        "method",
        "demo scores min / median / max",
        "own cut",
        "diagnostics",
    ]
    rows = []
    for c in data.curation:
        s = np.asarray(c.scores, float)
        spread = f"{s.min():.3g} / {np.median(s):.3g} / {s.max():.3g}" if s.size else "–"
        rep = c.report
        if c.method == "deminf":
            cut = f"lowest {100 * rep.get('drop_fraction', 0.2):g}% of demos"
            base = rep.get("base_demo_scores", {})
            diag = (
                f"I(S;A) ≈ {rep.get('mi_estimate', math.nan):.3g} nats over "
                f"{rep.get('n_pairs', '?')} pairs; D_base demos' mean score "
                f"{base.get('mean', math.nan):.3g}"
            )
        elif c.method in ("cupid", "quality"):
            cut = "–" if c.threshold is None else f"score <= {c.threshold:.3g}"
            diag = (
                f"{rep.get('rollouts')} noisy rollouts ({rep.get('rollout_successes')} "
                f"successes); {rep.get('negative_demos')} demos of negative influence"
                if c.method == "cupid"
                else f"{rep.get('flagged')} demos flagged ({rep.get('flags')})"
            )
        else:
            cut = "–" if c.threshold is None else f"score <= {c.threshold:.3g}"
            ckpts = ", ".join(
                f"{k['epoch']}: {k['successes']}/{k['rollouts']}"
                for k in rep.get("checkpoints", [])
            )
            diag = f"rollout successes per epoch {ckpts}"
            if c.trusted:
                diag += (
                    f"; trained on epoch {rep.get('chosen_train_epoch')}, validated on "
                    f"{rep.get('validation_epoch')}: rollout balanced accuracy "
                    f"{rep.get('validation_balanced_accuracy', math.nan):.2f}"
                )
                if at_chance(rep):
                    diag += " (no better than chance: the ranking carries no signal)"
        if not c.trusted:
            diag += f"; NO SIGNAL ({rep.get('why', '')}): nothing dropped"
        rows.append(
            [
                c.task,
                c.model or "–",
                c.operator,
                METHOD_LABELS.get(c.method, c.method),
                spread,
                cut,
                diag,
            ]
        )
    return header, rows


def sensitivity_tables(data: ReportData) -> list[tuple[str, Table]]:
    """Per task × model: held-out success of Base, Naive and M-Filtered at each λ point, with
    the paired interval of each point's difference from Naive."""
    rows_of = _rows(data.heldout)
    out = []
    for task, model in dict.fromkeys((r.task, r.model) for r in data.heldout):
        pts = sorted(
            (p for p in data.lambda_points if (p.task, p.model) == (task, model)),
            key=lambda p: p.point,
        )
        by_point: dict[tuple, list[ResultRow]] = {}
        for r in data.heldout:
            if (r.task, r.model, r.method) == (task, model, "filtered"):
                by_point.setdefault((r.operator, r.point), []).append(r)
        base = rows_of.get((task, model, "base", None), [])
        header = [
            "operator",
            "Naive",
            *[f"λ = {p.lambda_:.4g}" for p in pts],
        ]
        rows = [[f"base only: {mean_std([r.success for r in base])}", "", *["" for _ in pts]]]
        ops = list(
            dict.fromkeys(
                r.operator
                for r in data.heldout
                if r.operator and (r.task, r.model) == (task, model)
            )
        )
        for op in ops:
            naive = rows_of.get((task, model, "naive", op), [])
            vs_base = paired_diff(naive, base) if naive and base else None
            cells = [f"{mean_std([r.success for r in naive])}; vs Base {format_diff(vs_base)}"]
            for p in pts:
                mine = by_point.get((op, p.point), [])
                diff = paired_diff(mine, naive) if mine and naive else None
                cells.append(f"{mean_std([r.success for r in mine])}; Δ {format_diff(diff)}")
            rows.append([op, *cells])
        seeds = sorted({r.seed for r in data.heldout if (r.task, r.model) == (task, model)})
        lo_hi = f"{pts[0].low:.4g} .. {pts[0].high:.4g}, fitted {pts[0].fitted:.4g}" if pts else "?"
        title = (
            f"{task} — {model}: λ sensitivity across the fitted margin (λ {lo_hi}); held-out "
            f"training seeds {seeds} and initial states; success % mean (std), Δ from Naive"
        )
        out.append((title, (header, rows)))
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
    header = ["task", "model", "operator", "filter", "pairs kept", "episodes kept", "note"]
    rows = [
        [
            f.task,
            f.model,
            f.operator,
            METHOD_LABELS.get(f.method, f.method),
            f"{f.pairs_kept}/{f.pairs_total} ({_pct(f.pairs_kept, f.pairs_total)})",
            f"{f.episodes_kept}/{f.episodes_total}",
            f.note,
        ]
        for f in data.filters
    ]
    return header, rows


def length_table(data: ReportData) -> Table:
    """Mean demonstration length per operator (steps), with std over episodes."""
    header = ["task", "demo set", "operator", "episodes", "mean length (std)"]
    rows = [
        [
            r.task,
            r.name,
            r.operator,
            str(r.n_episodes),
            f"{r.mean_length:.1f} ({r.std_length:.1f})"
            if r.n_episodes > 1
            else f"{r.mean_length:.1f} (–)",
        ]
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
        "selected checkpoint per seed (epoch; best: lowest validation loss)",
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
