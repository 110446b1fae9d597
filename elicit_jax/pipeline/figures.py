"""Report figures drawn from gathered results: the λ-sensitivity curve.

One panel per task × model: held-out success rate of the M-filtered policy of each operator
at each λ point across the fitted margin (mean over held-out training seeds, bars at the 95%
t interval of the mean), with the operator's naive success as a dashed line of the same colour
and the fitted λ as a vertical line. PNG via matplotlib's Agg backend.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from elicit_jax.pipeline.tables import ReportData
from elicit_jax.stats import t_quantile

_PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")


def _mean_ci(values: list[float]) -> tuple[float, float]:
    """Mean and half-width of its 95% t interval (0 with one value), in percent."""
    v = 100.0 * np.asarray(values, float)
    if v.size < 2:
        return float(v.mean()), 0.0
    return float(v.mean()), t_quantile(v.size - 1) * float(v.std(ddof=1)) / math.sqrt(v.size)


def sensitivity_figure(data: ReportData, out: str | Path) -> list[tuple[str, str]]:
    """Draw the λ curves of ``data`` into ``out`` (one PNG); returns ``[(caption, path)]``,
    empty when the run has no sensitivity results."""
    cells = list(dict.fromkeys((p.task, p.model) for p in data.lambda_points))
    cells = [c for c in cells if any((r.task, r.model) == c for r in data.heldout)]
    if not cells:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(cells), figsize=(5.5 * len(cells), 5), squeeze=False)
    for ax, (task, model) in zip(axes[0], cells, strict=True):
        pts = sorted(
            (p for p in data.lambda_points if (p.task, p.model) == (task, model)),
            key=lambda p: p.point,
        )
        rows = [r for r in data.heldout if (r.task, r.model) == (task, model)]
        ops = list(dict.fromkeys(r.operator for r in rows if r.operator))
        for i, op in enumerate(ops):
            color = _PALETTE[i % len(_PALETTE)]
            stats = [
                _mean_ci([r.success for r in rows if (r.method, r.operator, r.point) ==
                          ("filtered", op, p.point)] or [math.nan])
                for p in pts
            ]  # fmt: skip
            ax.errorbar(
                [p.lambda_ for p in pts],
                [m for m, _ in stats],
                yerr=[h for _, h in stats],
                color=color,
                marker="o",
                capsize=3,
                label=f"{op}: M-filtered",
            )
            naive = [r.success for r in rows if (r.method, r.operator) == ("naive", op)]
            if naive:
                ax.axhline(100 * np.mean(naive), color=color, ls="--", lw=1, label=f"{op}: naive")
        base = [r.success for r in rows if r.method == "base"]
        if base:
            ax.axhline(100 * np.mean(base), color="black", ls=":", lw=1, label="base only")
        if pts:
            ax.axvline(pts[0].fitted, color="grey", lw=1)
            ax.text(pts[0].fitted, 1, " fitted λ", color="grey", fontsize=8, va="bottom")
        ax.set_xlabel("λ (likelihood-error threshold; η as fitted)")
        ax.set_ylabel("held-out success %")
        ax.set_ylim(0, 100)
        ax.set_title(f"{task}, {model}")
        ax.legend(
            fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False
        )
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)
    caption = (
        "λ sensitivity: held-out success of the M-filtered policy across the fitted margin "
        "(mean over held-out seeds, bars: 95% t interval), naive (dashed) and base (dotted)"
    )
    return [(caption, str(out))]
