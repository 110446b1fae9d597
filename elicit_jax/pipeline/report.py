"""Render a pipeline run as Markdown and as one self-contained HTML page.

The content comes from :mod:`elicit_jax.pipeline.tables`; :func:`render_markdown` and
:func:`render_html` turn it into text; what every report kind shares (first lines, closing
blocks, the folder) is :mod:`elicit_jax.pipeline.report_folder`'s. The HTML page inlines its
PNG maps as base64 and uses no external asset.
"""

from __future__ import annotations

import base64
import dataclasses
import html
from pathlib import Path
from typing import Any

from elicit_jax.pipeline.across import across_note, across_tables
from elicit_jax.pipeline.evidence import selection_lines, write_data
from elicit_jax.pipeline.render import html_document, markdown_document
from elicit_jax.pipeline.report_folder import (
    CPU_NOTE,
    intro_lines,
    provenance_blocks,
    write_report_folder,
)
from elicit_jax.pipeline.tables import (
    INTERVAL_NOTE,
    STD_NOTE,
    ReportData,
    curation_table,
    decisions_table,
    difference_tables,
    filter_table,
    length_table,
    models_table,
    results_tables,
    rollout_length_table,
    sensitivity_tables,
    threshold_table,
)
from elicit_jax.pipeline.tables_sizes import sizes_heading, sizes_note, sizes_tables


def _sections(data: ReportData) -> list[tuple[str, Any]]:
    """Ordered (title, content) blocks shared by both renderers; content is a Table, text,
    a list of maps or a code block (``("code", text)``)."""
    blocks: list[tuple[str, Any]] = [*sizes_tables(data), *across_tables(data)]
    diffs = difference_tables(data)
    for (title, table), diff in zip(results_tables(data), diffs, strict=True):
        blocks += [(title, table), diff]
    for title, table in models_table(data):
        blocks.append((title, table))
    for title, table in sensitivity_tables(data):
        blocks.append((title, table))
    if data.figures:
        blocks.append(("λ sensitivity", list(data.figures)))
    blocks.append(("Mean rollout length and selected checkpoints", rollout_length_table(data)))
    if data.thresholds:
        blocks.append(
            ("Threshold fit (contrast sets disjoint from every D_new)", threshold_table(data))
        )
        blocks.append(("Contrast-set decisions under the thresholds", decisions_table(data)))
    if data.filters:
        blocks.append(("What the filters kept", filter_table(data)))
    if data.curation:
        blocks.append(
            (
                "Curation baselines: per-demonstration scores (DemInf, Demo-SCORE)",
                curation_table(data),
            )
        )
    if data.maps:
        blocks.append(("Compatibility maps (per operator)", list(data.maps)))
    if data.lengths:
        blocks.append(("Mean demonstration length per operator", length_table(data)))
    return blocks + provenance_blocks(data, "Pipeline definition")


def _intro(data: ReportData) -> list[str]:
    lines = intro_lines(data, "Pipeline")
    lines += list(data.notes)
    lines += sizes_note(data)
    lines += selection_lines((*data.results, *data.heldout))
    if data.results or data.heldout:
        lines.append(f"Differences between policies: {INTERVAL_NOTE}")
        lines.append(STD_NOTE)
        lines += across_note(data)
    return lines


def summary_tables(data: ReportData) -> list[tuple[str, Any]]:
    """The tables a finished run prints (the paper's layout): the sizes side by side of a run
    at several sizes, the across-collections tables of a study over several collections, then
    each results table followed by its differences from Naive with their paired 95%
    intervals, then the model comparison."""
    results = results_tables(data)
    paired = [t for pair in zip(results, difference_tables(data), strict=True) for t in pair]
    return sizes_tables(data) + across_tables(data) + paired + models_table(data)


def render_markdown(data: ReportData, map_dir: str = "") -> str:
    """The report as Markdown; maps are linked as files relative to the report."""

    def figure(_: str, item: tuple[str, str]) -> list[str]:
        caption, png = item
        return [f"![{caption}]({map_dir}{Path(png).name})", "", f"*{caption}*", ""]

    return markdown_document(_heading(data), _intro(data), data.findings, _sections(data), figure)


def render_html(data: ReportData) -> str:
    """The report as one self-contained HTML page (maps inlined as base64 PNG)."""

    def figure(_: str, item: tuple[str, str]) -> list[str]:
        caption, b64 = html.escape(item[0]), base64.b64encode(Path(item[1]).read_bytes()).decode()
        return [
            f'<figure><img alt="{caption}" src="data:image/png;base64,{b64}">'
            f"<figcaption>{caption}</figcaption></figure>"
        ]

    return html_document(
        f"elicit-jax report: {data.pipeline}",
        _heading(data),
        _intro(data),
        [CPU_NOTE],
        data.findings,
        _sections(data),
        figure,
    )


def _heading(data: ReportData) -> str:
    return f"elicit-jax report: {data.pipeline} ({data.profile} profile{sizes_heading(data)})"


def write_report(
    data: ReportData,
    out_dir: str | Path,
    rollouts: Any = None,
    rebuilt_from: Path | None = None,
) -> tuple[Path, Path]:
    """Atomically write ``out_dir/`` with ``report.md``, ``report.html``, ``maps/*.png``,
    the raw results (``rollouts.parquet``, ``report-data.json``) and ``artifact.json``
    (:func:`~elicit_jax.pipeline.report_folder.write_report_folder`); returns the Markdown
    and HTML paths.

    Args:
      data: what the report shows.
      out_dir: the report folder.
      rollouts: the per-rollout table the results were computed from (default
        ``data.rollouts``; ``None``: none kept, and the report says it cannot be rebuilt).
      rebuilt_from: a report folder being rebuilt: its raw-result files are copied as they
        are (byte for byte) instead of written anew.
    """
    if rollouts is not None:
        data = dataclasses.replace(data, rollouts=rollouts)
    return write_report_folder(
        data,
        out_dir,
        kind="pipeline-report",
        write_data=write_data,
        draw=_draw,
        render=lambda d: (render_markdown(d, map_dir="maps/"), render_html(d)),
        rebuilt_from=rebuilt_from,
    )


def _draw(folder: Path, data: ReportData) -> tuple[ReportData, list[str]]:
    """Copy the maps into ``folder/maps`` and draw the λ-sensitivity figure there."""
    from elicit_jax.pipeline.figures import sensitivity_figure

    (folder / "maps").mkdir()
    for _, png in data.maps:
        (folder / "maps" / Path(png).name).write_bytes(Path(png).read_bytes())
    figures = sensitivity_figure(data, folder / "maps" / "lambda-sensitivity.png")
    return dataclasses.replace(data, figures=tuple(figures)), []
