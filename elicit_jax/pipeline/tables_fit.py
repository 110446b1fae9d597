"""The report's tables of what happened before training: threshold fits and their contrast-set
decisions, what each filter kept, the curation baselines' per-demonstration scores, and the
demonstration sets' lengths. Rows of a later collection name it beside the task.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from elicit_jax.pipeline.report_rows import (
    METHOD_LABELS,
    ReportData,
    Table,
    several_collections,
    task_label,
)


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
                task_label(c.task, c.collection, several_collections(data.curation)),
                c.model or "–",
                c.operator,
                METHOD_LABELS.get(c.method, c.method),
                spread,
                cut,
                diag,
            ]
        )
    return header, rows


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
                task_label(t.task, t.collection, several_collections(data.thresholds)),
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
                    task_label(t.task, t.collection, several_collections(data.thresholds)),
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
            task_label(f.task, f.collection, several_collections(data.filters)),
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
            task_label(r.task, r.collection, several_collections(data.lengths)),
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


def _num(v: Any) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    return f"{v:.3g}" if isinstance(v, float) else str(v)


def _pct(a: int, b: int) -> str:
    return f"{100.0 * a / b:.1f}%" if b else "–"
