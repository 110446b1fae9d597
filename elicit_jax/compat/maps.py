"""Compatibility maps: every pair at (likelihood error ℓ, novelty ν), one panel per operator.

The x axis is ℓ on a log scale (``x="likelihood-error"``) or, as in the paper's figures,
likelihood as ``−ℓ`` (``x="neg-likelihood-error"``: the same log-magnitude axis reversed, so
more likely is to the right). The incompatible region ``ℓ > λ, ν < η`` is drawn as a red box;
density is a 2-D histogram (log counts) so overlapping points stay readable. Outputs a PNG
(matplotlib, Agg) and, for ``.html`` paths, a self-contained interactive page (inline SVG and
JavaScript, no network): hover a point for its episode, step, ℓ, ν and M; click an operator in
the legend to hide it.

Example:
    >>> write_map(scores, 0.4, 0.05, "map.png")
"""

from __future__ import annotations

import dataclasses
import html
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import atomic_path
from elicit_jax.compat.measures import is_incompatible
from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.errors import ElicitError
from elicit_jax.render import html_page

AXES = ("likelihood-error", "neg-likelihood-error")
FLOOR = 1e-6
_PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2")


def _log_ell(ell: np.ndarray) -> np.ndarray:
    return np.log10(np.maximum(np.asarray(ell, np.float64), FLOOR))


def _ranges(ell: np.ndarray, nu: np.ndarray, t: Thresholds) -> tuple[float, ...]:
    lam, eta = t.pair
    lx = _log_ell(ell)
    x0 = min(float(np.quantile(lx, 0.001)), np.log10(lam)) - 0.2
    x1 = max(float(lx.max()), np.log10(lam)) + 0.2
    y1 = max(float(np.quantile(nu, 0.999)), eta) * 1.1 + 1e-9
    return x0, x1, 0.0, y1


def _ticks(x0: float, x1: float, most: int = 6) -> np.ndarray:
    """Integer log10 tick positions in [x0, x1], at most ``most`` of them."""
    ticks = np.arange(np.ceil(x0), np.floor(x1) + 1)
    step = max(1, -(-len(ticks) // most))
    return ticks[::step]


def _x_label(axis: str) -> str:
    if axis == "likelihood-error":
        return "likelihood error ℓ (log scale; right = less likely)"
    return "likelihood −ℓ (log magnitude; right = more likely)"


def write_png(
    scores: Mapping[str, np.ndarray],
    thresholds: Thresholds,
    out: str | Path,
    axis: str = "likelihood-error",
    bins: int = 60,
) -> None:
    """Write the map as a PNG: one panel per operator, shared axes.

    Args:
      scores: per-pair ``likelihood``, ``novelty``, ``operator`` (and ``incompatible``).
      thresholds: (λ, η) of the box.
      out: PNG path.
      axis: :data:`AXES`.
      bins: histogram bins per axis.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Rectangle

    if axis not in AXES:
        raise ElicitError(f"unknown axis '{axis}' (choose {', '.join(AXES)})")
    ell, nu = np.asarray(scores["likelihood"]), np.asarray(scores["novelty"])
    lambda_, eta = thresholds.pair
    ops = np.asarray(scores["operator"]).astype(str)
    names = sorted(set(ops.tolist()))
    x0, x1, y0, y1 = _ranges(ell, nu, thresholds)
    xe, ye = np.linspace(x0, x1, bins + 1), np.linspace(y0, y1, bins + 1)
    ncol = min(3, len(names))
    nrow = -(-len(names) // ncol)
    fig, axes = plt.subplots(
        nrow, ncol, figsize=(4.2 * ncol, 3.6 * nrow), squeeze=False, sharex=True, sharey=True
    )
    sign = -1 if axis == "neg-likelihood-error" else 1
    for k, ax in enumerate(axes.ravel()):
        if k >= len(names):
            ax.set_visible(False)
            continue
        sel = ops == names[k]
        hist, _, _ = np.histogram2d(_log_ell(ell[sel]), nu[sel], bins=(xe, ye))
        hist = np.where(hist > 0, hist, np.nan)
        mesh = ax.pcolormesh(sign * xe, ye, hist.T, cmap="viridis", norm=LogNorm(), alpha=0.9)
        lx = np.log10(lambda_)
        width = (x1 - lx) * sign
        ax.add_patch(
            Rectangle((sign * lx, 0), width, eta, fill=True, color="red", alpha=0.15, lw=0)
        )
        ax.add_patch(Rectangle((sign * lx, 0), width, eta, fill=False, ec="red", lw=1.5))
        ax.axvline(sign * lx, color="red", ls="--", lw=0.8)
        ax.axhline(eta, color="red", ls="--", lw=0.8)
        inc = float(is_incompatible(ell[sel], nu[sel], lambda_, eta).mean())
        ax.set_title(
            f"{names[k]}\n{int(sel.sum())} pairs, {100 * inc:.1f}% incompatible", fontsize=10
        )
        fig.colorbar(mesh, ax=ax, label="pairs")
        ax.set_xlim(sorted((sign * x0, sign * x1)))
        ax.set_ylim(y0, y1)
        ticks = _ticks(x0, x1)
        ax.set_xticks(sign * ticks)
        ax.set_xticklabels([f"${'-' if sign < 0 else ''}10^{{{int(t)}}}$" for t in ticks])
        if k // ncol == nrow - 1:
            ax.set_xlabel(_x_label(axis))
        if k % ncol == 0:
            ax.set_ylabel("novelty ν")
    fig.suptitle(f"compatibility map (red box: incompatible, λ={lambda_:.3g}, η={eta:.3g})")
    fig.tight_layout()
    with atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def _subsample(n: int, limit: int, seed: int = 0) -> np.ndarray:
    if n <= limit:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size=limit, replace=False))


def write_html(
    scores: Mapping[str, np.ndarray],
    thresholds: Thresholds,
    out: str | Path,
    axis: str = "likelihood-error",
    max_points: int = 4000,
    bins: int = 50,
) -> None:
    """Write a self-contained interactive HTML map (inline SVG + JS, no network access).

    Args:
      scores: per-pair ``likelihood``, ``novelty``, ``compatibility``, ``operator``,
        ``episode``, ``step``.
      thresholds: (λ, η) of the box.
      out: HTML path.
      axis: :data:`AXES`.
      max_points: points drawn per operator (a seeded subsample; the density uses all).
      bins: density histogram bins per axis.
    """
    if axis not in AXES:
        raise ElicitError(f"unknown axis '{axis}' (choose {', '.join(AXES)})")
    ell, nu = np.asarray(scores["likelihood"]), np.asarray(scores["novelty"])
    lambda_, eta = thresholds.pair
    frame = _Frame(*_ranges(ell, nu, thresholds), sign=-1 if axis == AXES[1] else 1)
    parts = _density_svg(frame, ell, nu, bins) + _axes_svg(frame, thresholds, axis)
    points, legend = _points_svg(frame, scores, max_points)
    w, h = _SVG_SIZE
    svg = f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}">'
    svg += "".join(parts + points) + "</svg>"
    title = f"compatibility map (λ={lambda_:.3g}, η={eta:.3g})"
    body = _BODY.format(title=html.escape(title), legend=" ".join(legend), svg=svg)
    with atomic_path(out) as tmp:
        tmp.write_text(html_page(title, body, _CSS), encoding="utf-8")


_SVG_SIZE, _SVG_PAD = (760, 480), 60


@dataclasses.dataclass(frozen=True)
class _Frame:
    """The SVG plot area: data ranges (x in log10 ℓ) and the x direction (``sign``)."""

    x0: float
    x1: float
    y0: float
    y1: float
    sign: int

    def px(self, lx: np.ndarray | float) -> Any:
        w, pad = _SVG_SIZE[0], _SVG_PAD
        frac = (np.asarray(lx) - self.x0) / (self.x1 - self.x0)
        return pad + (frac if self.sign > 0 else 1 - frac) * (w - 2 * pad)

    def py(self, v: np.ndarray | float) -> Any:
        h, pad = _SVG_SIZE[1], _SVG_PAD
        return h - pad - (np.asarray(v) - self.y0) / (self.y1 - self.y0) * (h - 2 * pad)


def _density_svg(f: _Frame, ell: np.ndarray, nu: np.ndarray, bins: int) -> list[str]:
    """Grey cells of the 2-D histogram of every pair (log-scaled opacity)."""
    rng = ((f.x0, f.x1), (f.y0, f.y1))
    hist, xe, ye = np.histogram2d(_log_ell(ell), nu, bins=bins, range=rng)
    top = np.log1p(hist.max()) or 1.0
    parts = []
    for i, j in zip(*np.nonzero(hist), strict=True):
        a, b = sorted((float(f.px(xe[i])), float(f.px(xe[i + 1]))))
        parts.append(
            f'<rect x="{a:.1f}" y="{f.py(ye[j + 1]):.1f}" width="{b - a:.1f}" '
            f'height="{f.py(ye[j]) - f.py(ye[j + 1]):.1f}" fill="#444" '
            f'fill-opacity="{0.45 * np.log1p(hist[i, j]) / top:.3f}"/>'
        )
    return parts


def _axes_svg(f: _Frame, thresholds: Thresholds, axis: str) -> list[str]:
    lambda_, eta = thresholds.pair
    """The incompatible box, the tick labels, the axis titles and the frame."""
    (w, h), pad = _SVG_SIZE, _SVG_PAD
    bx = sorted((float(f.px(np.log10(lambda_))), float(f.px(f.x1))))
    parts = [
        f'<rect x="{bx[0]:.1f}" y="{f.py(eta):.1f}" width="{bx[1] - bx[0]:.1f}" '
        f'height="{f.py(0) - f.py(eta):.1f}" fill="red" fill-opacity="0.12" stroke="red"/>'
    ]
    for t in _ticks(f.x0, f.x1):
        lab = f"{'−' if f.sign < 0 else ''}1e{int(t)}"
        parts.append(
            f'<text x="{f.px(t):.1f}" y="{h - pad + 18}" text-anchor="middle">{lab}</text>'
        )
    for v in np.linspace(f.y0, f.y1, 5):
        parts.append(f'<text x="{pad - 6}" y="{f.py(v):.1f}" text-anchor="end">{v:.3g}</text>')
    parts.append(
        f'<text x="{w / 2}" y="{h - 12}" text-anchor="middle">{html.escape(_x_label(axis))}'
        f'</text><text x="14" y="{h / 2}" transform="rotate(-90 14 {h / 2})" '
        'text-anchor="middle">novelty ν</text>'
        f'<rect x="{pad}" y="{pad}" width="{w - 2 * pad}" height="{h - 2 * pad}" '
        'fill="none" stroke="#888"/>'
    )
    return parts


def _points_svg(
    f: _Frame, scores: Mapping[str, np.ndarray], max_points: int
) -> tuple[list[str], list[str]]:
    """One group of points per operator (a seeded subsample, each with its hover data) and
    the legend's checkboxes."""
    ell, nu = np.asarray(scores["likelihood"]), np.asarray(scores["novelty"])
    ops = np.asarray(scores["operator"]).astype(str)
    comp = np.asarray(scores.get("compatibility", np.ones(len(ell))))
    ep, st = np.asarray(scores["episode"]), np.asarray(scores["step"])
    parts, legend = [], []
    for k, name in enumerate(sorted(set(ops.tolist()))):
        color = _PALETTE[k % len(_PALETTE)]
        idx = np.flatnonzero(ops == name)[_subsample(int((ops == name).sum()), max_points, k)]
        cx, cy = f.px(_log_ell(ell[idx])), f.py(np.clip(nu[idx], f.y0, f.y1))
        dots = "".join(
            f'<circle cx="{a:.1f}" cy="{b:.1f}" r="2.2" data-t="{int(ep[i])},{int(st[i])},'
            f'{ell[i]:.4g},{nu[i]:.4g},{comp[i]:.3f}"/>'
            for a, b, i in zip(cx, cy, idx, strict=True)
        )
        op_id = '"' + html.escape(name, quote=True) + '"'
        parts.append(f'<g class="op" data-op={op_id} fill="{color}" fill-opacity="0.55">{dots}</g>')
        legend.append(
            f'<label style="color:{color}"><input type="checkbox" checked data-op={op_id}> '
            f"{html.escape(name)} ({int((ops == name).sum())} pairs)</label>"
        )
    return parts, legend


_CSS = """body{font:13px sans-serif;margin:16px}text{font:11px sans-serif}
#tip{position:fixed;background:#fff;border:1px solid #888;padding:4px;display:none}
label{margin-right:12px;cursor:pointer}"""

_BODY = """<h3>{title}</h3><p>Red box: incompatible pairs (ℓ &gt; λ, ν &lt; η). Grey: density of all
pairs. Hover a point for details; untick an operator to hide it.</p><div>{legend}</div>{svg}
<div id="tip"></div>
<script>
const tip = document.getElementById("tip");
document.querySelectorAll("circle").forEach(c => {{
  c.addEventListener("mouseenter", e => {{
    const [ep, st, l, n, m] = c.dataset.t.split(",");
    const op = c.parentNode.dataset.op;
    tip.textContent = `${{op}} episode ${{ep}} step ${{st}}: ℓ=${{l}} ν=${{n}} M=${{m}}`;
    tip.style.left = (e.clientX + 12) + "px"; tip.style.top = (e.clientY + 12) + "px";
    tip.style.display = "block";
  }});
  c.addEventListener("mouseleave", () => {{ tip.style.display = "none"; }});
}});
document.querySelectorAll("input[data-op]").forEach(box => {{
  box.addEventListener("change", () => {{
    document.querySelectorAll("g.op").forEach(g => {{
      if (g.dataset.op === box.dataset.op) g.style.display = box.checked ? "" : "none";
    }});
  }});
}});
</script>"""


def write_map(
    scores: Mapping[str, np.ndarray],
    thresholds: Thresholds,
    out: str | Path,
    axis: str = "likelihood-error",
) -> None:
    """Write a PNG or (for ``.html``/``.htm`` paths) an interactive HTML map."""
    if Path(out).suffix.lower() in (".html", ".htm"):
        write_html(scores, thresholds, out, axis)
    elif Path(out).suffix.lower() == ".png":
        write_png(scores, thresholds, out, axis)
    else:
        raise ElicitError("map output must end in .png or .html", out)


def map_scores_file(
    scores_path: str | Path,
    out: str | Path,
    thresholds: Thresholds,
    axis: str = "likelihood-error",
) -> None:
    """Draw the map of a scores file under ``thresholds`` (those it was scored with, or others:
    :func:`~elicit_jax.compat.threshold_source.applied_thresholds` chooses)."""
    from elicit_jax.artifact import refuse_overwriting_inputs
    from elicit_jax.compat.score_file import read_scores

    refuse_overwriting_inputs([out], [scores_path])
    _, scores = read_scores(
        scores_path,
        columns=["episode", "operator", "step", "likelihood", "novelty", "compatibility"],
    )
    write_map(scores, thresholds, out, axis)
