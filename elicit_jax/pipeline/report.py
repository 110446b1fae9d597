"""A filtering study's report (:data:`LAYOUT`): its tables, figures and intro, for the one
report path of every study kind (:func:`elicit_jax.pipeline.report_folder.write_report`:
Markdown and one self-contained HTML page, which inlines its PNG maps as base64 and uses no
external asset).

The content comes from :mod:`elicit_jax.pipeline.tables`; what every report kind shares (first
lines, findings, closing blocks, the folder) is :mod:`elicit_jax.pipeline.report_folder`'s.
"""

from __future__ import annotations

import base64
import dataclasses
import html
from pathlib import Path
from typing import Any

from elicit_jax.pipeline.across import across_note, across_tables
from elicit_jax.pipeline.evidence import data_to_json, selection_lines
from elicit_jax.pipeline.report_folder import ReportLayout, intro_lines
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
from elicit_jax.pipeline.tables_conflicts import conflict_tables
from elicit_jax.pipeline.tables_sizes import sizes_heading, sizes_note, sizes_tables
from elicit_jax.render import FigureRenderer


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
    blocks += conflict_tables(data)
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
    return blocks


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


def _figures(_: Path) -> tuple[FigureRenderer, FigureRenderer]:
    """Maps and the λ-sensitivity figure: linked under ``maps/`` in Markdown, inlined from
    their files as base64 PNG in HTML."""

    def markdown(_: str, item: tuple[str, str]) -> list[str]:
        caption, png = item
        return [f"![{caption}](maps/{Path(png).name})", "", f"*{caption}*", ""]

    def page(_: str, item: tuple[str, str]) -> list[str]:
        caption, b64 = html.escape(item[0]), base64.b64encode(Path(item[1]).read_bytes()).decode()
        return [
            f'<figure><img alt="{caption}" src="data:image/png;base64,{b64}">'
            f"<figcaption>{caption}</figcaption></figure>"
        ]

    return markdown, page


def _draw(folder: Path, data: ReportData) -> tuple[ReportData, list[str]]:
    """Copy the maps into ``folder/maps`` and draw the λ-sensitivity figure there."""
    from elicit_jax.pipeline.figures import sensitivity_figure

    (folder / "maps").mkdir()
    for _, png in data.maps:
        (folder / "maps" / Path(png).name).write_bytes(Path(png).read_bytes())
    figures = sensitivity_figure(data, folder / "maps" / "lambda-sensitivity.png")
    return dataclasses.replace(data, figures=tuple(figures)), []


LAYOUT = ReportLayout(
    kind="pipeline-report",
    title="elicit-jax report",
    definition="Pipeline definition",
    notes=(),
    intro=_intro,
    sections=lambda data, _: _sections(data),
    draw=_draw,
    figures=_figures,
    to_json=data_to_json,
    heading=sizes_heading,
)
"""A filtering (or models) study's report, for
:func:`~elicit_jax.pipeline.report_folder.write_report`: the sizes side by side of a run at
several named sizes (its heading and intro name them), the paper's tables with their
differences, the models and λ-sensitivity tables, the share of the demos that conflict
(measured per demo, when the demos carry it), the fit, the filters, the curation scores, the
maps and the demonstration lengths."""
