"""Pictures and pages of demonstrations: M over time, flagged windows, the base segment beside.

:func:`demo_figure` draws one demonstration: M per step with the flagged windows shaded, then
for the worst window the observation fields that differ most — the operator's states solid,
the retrieved base segment's dashed, aligned step by step. :func:`write_demo_page` writes it as
a PNG and a self-contained HTML page (the PNG inlined, no external asset) with the package's
renderer (:mod:`elicit_jax.render`); :data:`PAGE_CSS` is the session pages' stylesheet.
Figures use matplotlib's object API with the Agg canvas (no global backend state).
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import atomic_path
from elicit_jax.elicit.events import WindowFeedback
from elicit_jax.render import CSS, figure_png, html_page, html_table, img_tag

PAGE_CSS = CSS + "th,td{vertical-align:top}.accepted{color:#1a7f37}.rejected,.failed{color:#b42318}"


def demo_figure(
    compatibility: np.ndarray,
    feedback: Sequence[WindowFeedback],
    obs: np.ndarray,
    base: Any,
    title: str,
    n_fields: int = 2,
) -> Any:
    """M over time with the windows shaded; the worst window's most different fields beside
    the base segment's.

    Args:
      compatibility: (T,) M per scored step.
      feedback: the windows (worst first), possibly empty.
      obs: (T, O) the scored steps' states.
      base: the base ``Demos`` (for the retrieved segments).
      title: figure title.
      n_fields: how many observation fields to draw for the worst window.
    """
    from matplotlib.figure import Figure

    fields = list(feedback[0].fields[:n_fields]) if feedback else []
    fig = Figure(figsize=(9, 2.6 + 2.2 * len(fields)))
    axes = fig.subplots(1 + len(fields), 1, squeeze=False)[:, 0]
    ax = axes[0]
    m = np.asarray(compatibility)
    ax.plot(np.arange(len(m)), m, color="#1f77b4", lw=1)
    ax.fill_between(np.arange(len(m)), 0, 1, where=m <= 0, color="#d62728", alpha=0.15, lw=0)
    for i, fb in enumerate(feedback):
        ax.axvspan(fb.start - 0.5, fb.stop - 0.5, color="#ff7f0e", alpha=0.3, lw=0)
        ax.text(fb.start, 1.02, f"#{i + 1}", fontsize=8)
    ax.set_ylim(-0.05, 1.1)
    ax.set_ylabel("M")
    ax.set_xlabel("step (red: incompatible; orange: flagged windows)")
    ax.set_title(title, fontsize=10)
    if fields:
        fb = feedback[0]
        rows = {e: (s, t) for e, s, t in base.episode_bounds()}
        s0 = rows[fb.base_episode][0]
        spans = {f.name: (f.start, f.stop) for f in base.obs_fields}
        seg = base.obs[s0 + fb.base_start : s0 + fb.base_stop]
        idx = np.rint(np.linspace(0, len(seg) - 1, fb.stop - fb.start)).astype(int)
        steps = np.arange(fb.start, fb.stop)
        for ax, d in zip(axes[1:], fields, strict=True):
            a, b = spans.get(d.name, (0, obs.shape[1]))
            for j, dim in enumerate(range(a, min(b, a + 4))):
                color = f"C{j}"
                ax.plot(steps, obs[fb.start : fb.stop, dim], color=color, lw=1.5)
                ax.plot(steps, seg[idx, dim], color=color, lw=1.5, ls="--")
            ax.set_title(
                f"window #1, {d.name}: yours (solid) vs base demo {fb.base_episode} "
                f"steps {fb.base_start}–{fb.base_stop - 1} (dashed)",
                fontsize=9,
            )
    fig.tight_layout()
    return fig


def write_demo_page(
    html_path: Path,
    png_path: Path,
    *,
    title: str,
    verdict: str,
    summary: Sequence[tuple[str, Any]],
    compatibility: np.ndarray,
    feedback: Sequence[WindowFeedback],
    obs: np.ndarray,
    base: Any,
) -> None:
    """Write the PNG and the self-contained HTML page of one demonstration (atomically)."""
    png = figure_png(demo_figure(compatibility, feedback, obs, base, title))
    with atomic_path(png_path) as tmp:
        tmp.write_bytes(png)
    windows = html_table(
        ["#", "steps", "1−M", "base demo", "base steps", "what differs"],
        [
            (
                i + 1,
                f"{f.start}–{f.stop - 1}",
                f"{f.incompatibility:.2f}",
                f.base_episode,
                f"{f.base_start}–{f.base_stop - 1}",
                f.text.split(": ", 1)[-1],
            )
            for i, f in enumerate(feedback)
        ],
    )
    body = (
        f"<h1>{html.escape(title)}</h1>"
        f'<p class="{html.escape(verdict)}"><b>{html.escape(verdict.upper())}</b></p>'
        + html_table(["", ""], summary)
        + img_tag(png, "M over time and the worst window")
        + "<h2>Flagged windows</h2>"
        + windows
    )
    with atomic_path(html_path) as tmp:
        tmp.write_text(html_page(title, body, PAGE_CSS))
