"""``fit-thresholds`` end to end: select contrast sets in a scores file, fit (or take given)
thresholds, report how well they separate the sets, write a ``thresholds`` artifact.

Example:
    >>> fit_scores_file("scores.parquet", "operator:base", "operator:op4", "thresholds.json")

The objective is explained in :mod:`elicit_jax.compat.thresholds` and ``docs/thresholds.md``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.compat.selection import parse_selection, select_episodes
from elicit_jax.compat.thresholds import (
    FitConfig,
    evaluate_thresholds,
    fit_thresholds,
    operator_rejections,
    write_thresholds,
)
from elicit_jax.errors import ElicitError


@dataclasses.dataclass(frozen=True)
class FitJob:
    """A ``fit-thresholds`` run.

    Attributes:
      compatible: selection text of the compatible set (``operator:…``, ``episodes:…``,
        ``label:col=value``).
      incompatible: selection text of the incompatible set.
      fit: fitting settings.
      lambda_: manual λ (with ``eta``): skip fitting, only evaluate and record.
      eta: manual η.
    """

    compatible: str
    incompatible: str
    fit: FitConfig = dataclasses.field(default_factory=FitConfig)
    lambda_: float | None = None
    eta: float | None = None


def contrast_labels(
    columns: dict[str, np.ndarray], compatible: str, incompatible: str
) -> dict[int, bool]:
    """Episode id -> True/False from two selections; errors when they overlap."""
    comp = select_episodes(parse_selection(compatible), columns)
    inc = select_episodes(parse_selection(incompatible), columns)
    both = sorted(set(comp.tolist()) & set(inc.tolist()))
    if both:
        raise ElicitError(
            f"episode(s) {both[:5]} are in both the compatible and the incompatible set"
        )
    return {**{int(e): True for e in comp}, **{int(e): False for e in inc}}


def fit_scores_file(
    scores_path: str | Path, out_path: str | Path, job: FitJob, *, show: bool = True
) -> dict[str, Any]:
    """Fit or evaluate thresholds on a scores file and write ``thresholds.json``.

    Args:
      scores_path: a ``scores`` artifact.
      out_path: the ``thresholds`` artifact to write.
      job: the contrast sets and settings.
      show: print the report as rich tables.

    Returns:
      The written header (``lambda``, ``eta``, ``report``, ...).
    """
    from elicit_jax.compat.score_file import read_scores

    if (job.lambda_ is None) != (job.eta is None):
        raise ElicitError("give both --lambda and --eta for a manual override, or neither")
    cols = [c for c in _needed(job) if c not in ("episode", "operator", "likelihood", "novelty")]
    _, s = read_scores(scores_path, columns=["episode", "operator", "likelihood", "novelty", *cols])
    labels = contrast_labels(s, job.compatible, job.incompatible)
    ell, nu, ep = s["likelihood"], s["novelty"], s["episode"]
    f = job.fit.accept_fraction
    if job.lambda_ is None:
        fit = fit_thresholds(ell, nu, ep, labels, job.fit)
        lam, eta, method = fit.lambda_, fit.eta, "fit"
        ba, decisions = fit.balanced_accuracy, fit.episodes
        extra = {
            "margin_steps": fit.margin_steps,
            "margin_quantile": fit.margin_quantile,
            "lambda_range": list(fit.lambda_range),
            "eta_range": list(fit.eta_range),
            "loo_accuracy": fit.loo_accuracy,
            "n_loo": fit.n_loo,
        }
    else:
        lam, eta, method = float(job.lambda_), float(job.eta), "manual"
        ba, decisions = evaluate_thresholds(ell, nu, ep, labels, lam, eta, f)
        extra = {}
    per_op = operator_rejections(ell, nu, ep, s["operator"], lam, eta, f)
    report = {
        "balanced_accuracy": ba,
        **extra,
        "n_compatible": int(np.sum(decisions["compatible"])),
        "n_incompatible": int(np.sum(~decisions["compatible"])),
        "contrast": [
            {
                "episode": int(e),
                "compatible": bool(c),
                "fraction_incompatible": float(fr),
                "rejected": bool(r),
            }
            for e, c, fr, r in zip(
                decisions["episode"],
                decisions["compatible"],
                decisions["fraction_incompatible"],
                decisions["rejected"],
                strict=True,
            )
        ],
        "per_operator": per_op,
    }
    config = {
        "compatible": job.compatible,
        "incompatible": job.incompatible,
        **dataclasses.asdict(job.fit),
    }
    header = write_thresholds(
        out_path,
        lambda_=lam,
        eta=eta,
        method=method,
        scores_path=scores_path,
        config=config,
        report=report,
    )
    if show:
        print_report(header)
    return header


def _needed(job: FitJob) -> list[str]:
    out = []
    for text in (job.compatible, job.incompatible):
        sel = parse_selection(text)
        if sel.kind == "label":
            out.append(sel.values[0])
    return out


def print_report(header: dict[str, Any]) -> None:
    """Rich tables: the thresholds and their quality, then rejections per operator."""
    from rich.console import Console
    from rich.table import Table

    rep = header["report"]
    console = Console()
    t = Table(title=f"thresholds ({header['method']})")
    t.add_column("quantity")
    t.add_column("value", justify="right")
    t.add_row("lambda", f"{header['lambda']:.4g}")
    t.add_row("eta", f"{header['eta']:.4g}")
    if rep.get("balanced_accuracy") is not None:
        t.add_row("balanced accuracy", f"{rep['balanced_accuracy']:.3f}")
    if "margin_steps" in rep:
        quantile = rep.get("margin_quantile", rep.get("margin"))
        t.add_row("margin (grid steps / quantile)", f"{rep['margin_steps']} / {quantile:.3f}")
    for key, label in (("lambda_range", "lambda"), ("eta_range", "eta")):
        if rep.get(key):
            lo, hi = rep[key]
            t.add_row(f"{label} range in margin", f"{lo:.4g} .. {hi:.4g}")
    if "loo_accuracy" in rep:
        loo = rep["loo_accuracy"]
        t.add_row(
            "leave-one-out accuracy",
            "n/a (one demo per set)" if loo is None else f"{loo:.3f} ({rep['n_loo']} held out)",
        )
    if "n_compatible" in rep:
        t.add_row(
            "contrast demos (compatible / incompatible)",
            f"{rep['n_compatible']} / {rep['n_incompatible']}",
        )
    console.print(t)
    ops = Table(title="rejections under these thresholds")
    for col in ("operator", "pairs", "incompatible pairs", "episodes", "rejected episodes"):
        ops.add_column(col, justify="left" if col == "operator" else "right")
    for op, r in rep.get("per_operator", {}).items():
        share = 100 * r["incompatible_pairs"] / max(r["pairs"], 1)
        ops.add_row(
            op,
            str(r["pairs"]),
            f"{r['incompatible_pairs']} ({share:.1f}%)",
            str(r["episodes"]),
            str(r["rejected_episodes"]),
        )
    console.print(ops)
