"""Render a pipeline run as Markdown and as one self-contained HTML page.

The content comes from :mod:`elicit_jax.pipeline.tables`; :func:`render_markdown` and
:func:`render_html` turn it into text. The HTML page inlines its PNG maps as base64 and uses no
external asset.
"""

from __future__ import annotations

import base64
import dataclasses
import html
from pathlib import Path
from typing import Any

from elicit_jax.artifact import atomic_path, dumps, provenance_line
from elicit_jax.pipeline.across import across_note, across_tables
from elicit_jax.pipeline.evidence import (
    DATA_FILE,
    ROLLOUTS_FILE,
    selection_lines,
    write_data,
    write_rollouts_table,
)
from elicit_jax.pipeline.findings import write_beside
from elicit_jax.pipeline.render import html_document, markdown_document
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

CPU_NOTE = (
    "**CPU profile**: network sizes and epochs are shrunk to fit a 2-core machine "
    "(sizes below); the numbers are not the paper's setting."
)


def _sections(data: ReportData) -> list[tuple[str, Any]]:
    """Ordered (title, content) blocks shared by both renderers; content is a Table, text,
    a list of maps or a code block (``("code", text)``)."""
    blocks: list[tuple[str, Any]] = list(across_tables(data))
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


def provenance_blocks(data: Any, definition_title: str) -> list[tuple[str, Any]]:
    """The closing blocks every report ends with: the definition's text, each stage's config
    and the library versions (``data`` has ``spec_text``, ``configs`` and ``versions``)."""
    return [
        (definition_title, ("code", data.spec_text or "(not recorded)")),
        ("Stage configs", ("code", dumps(dict(data.configs)))),
        ("Library versions", ("code", dumps(dict(data.versions)))),
    ]


def provenance_intro(data: Any) -> list[str]:
    """The first lines of every study report: where its numbers came from (the run's code
    commit, versions and command line; the seeds), and how to rebuild it from its folder."""
    seeds = sorted({r.seed for r in (*data.results, *getattr(data, "heldout", ()))})
    evals = sorted(
        {s for r in (*data.results, *getattr(data, "heldout", ())) for s in r.eval_seeds}
    )
    raw = (
        f"Raw results: `{ROLLOUTS_FILE}` (one row per rollout) and `{DATA_FILE}` beside this "
        "report; `elicit-jax report --rebuild <this folder>` recomputes every table, interval "
        "and figure from them."
        if getattr(data, "raw_results", False)
        else "Raw results: not kept beside this report, so it cannot be rebuilt from its folder."
    )
    return [
        provenance_line(data.provenance),
        f"Seeds: training {seeds or '–'}, evaluation {evals or '–'}. {raw}",
    ]


def _intro(data: ReportData) -> list[str]:
    lines = provenance_intro(data)
    lines.append(
        f"Pipeline **{data.pipeline}**, profile **{data.profile}**, run directory `{data.run_dir}`."
    )
    if data.profile == "cpu":
        lines.append(CPU_NOTE)
    if data.description:
        lines.append(data.description)
    lines += list(data.notes)
    lines += selection_lines((*data.results, *data.heldout))
    if data.results or data.heldout:
        lines.append(f"Differences between policies: {INTERVAL_NOTE}")
        lines.append(STD_NOTE)
        lines += across_note(data)
    return lines


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
    return f"elicit-jax report: {data.pipeline} ({data.profile} profile)"


def write_report(
    data: ReportData,
    out_dir: str | Path,
    rollouts: Any = None,
    rebuilt_from: Path | None = None,
) -> tuple[Path, Path]:
    """Atomically write ``out_dir/`` with ``report.md``, ``report.html``, ``maps/*.png``,
    the raw results (``rollouts.parquet``, ``report-data.json``) and ``artifact.json``;
    returns the Markdown and HTML paths.

    Args:
      data: what the report shows.
      out_dir: the report folder.
      rollouts: the per-rollout table the results were computed from (``None``: none kept,
        and the report says it cannot be rebuilt).
      rebuilt_from: a report folder being rebuilt: its raw-result files are copied as they
        are (byte for byte) instead of written anew.
    """
    from elicit_jax.artifact import make_header
    from elicit_jax.pipeline.figures import sensitivity_figure

    out_dir = Path(out_dir)
    with atomic_path(out_dir) as tmp:
        (tmp / "maps").mkdir(parents=True)
        if rebuilt_from is not None:
            for name in (ROLLOUTS_FILE, DATA_FILE):
                (tmp / name).write_bytes((rebuilt_from / name).read_bytes())
        elif rollouts is not None:
            write_rollouts_table(tmp / ROLLOUTS_FILE, rollouts, data.pipeline, data.profile)
            write_data(tmp / DATA_FILE, data)
        kept = [n for n in (ROLLOUTS_FILE, DATA_FILE) if (tmp / n).is_file()]
        data = dataclasses.replace(data, raw_results=bool(kept))
        for _, png in data.maps:
            (tmp / "maps" / Path(png).name).write_bytes(Path(png).read_bytes())
        figures = sensitivity_figure(data, tmp / "maps" / "lambda-sensitivity.png")
        data = dataclasses.replace(data, figures=tuple(figures))
        (tmp / "report.md").write_text(render_markdown(data, map_dir="maps/"))
        (tmp / "report.html").write_text(render_html(data))
        findings = write_beside(data.findings, tmp)
        seeds = sorted({r.seed for r in (*data.results, *data.heldout)})
        header = make_header(
            "pipeline-report",
            1,
            config={"pipeline": data.pipeline, "profile": data.profile},
            inputs={name: tmp / name for name in kept},
            seed=seeds[0] if seeds else None,
            training_seeds=seeds,
            run=dict(data.provenance),
            **({"rebuilt_from": str(rebuilt_from)} if rebuilt_from is not None else {}),
            n_results=len(data.results),
            files=[
                "report.md",
                "report.html",
                *kept,
                *([findings["file"]] if findings else []),
            ],
            **({"findings": findings} if findings else {}),
        )
        for entry in header["inputs"].values():
            entry["path"] = Path(entry["path"]).name
        (tmp / "artifact.json").write_text(dumps(header) + "\n")
    return out_dir / "report.md", out_dir / "report.html"
