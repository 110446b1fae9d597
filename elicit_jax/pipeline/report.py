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

from elicit_jax.artifact import atomic_path, dumps
from elicit_jax.pipeline.findings import html_section, markdown_section, write_beside
from elicit_jax.pipeline.tables import (
    INTERVAL_NOTE,
    ReportData,
    Table,
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


def _md_table(table: Table) -> str:
    header, rows = table
    esc = [[str(c).replace("|", "\\|") for c in row] for row in [header, *rows]]
    lines = ["| " + " | ".join(esc[0]) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in esc[1:]]
    return "\n".join(lines)


def _sections(data: ReportData) -> list[tuple[str, Any]]:
    """Ordered (title, content) blocks shared by both renderers; content is a Table, text,
    a list of maps or a code block (``("code", text)``)."""
    blocks: list[tuple[str, Any]] = []
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


def _intro(data: ReportData) -> list[str]:
    lines = [
        f"Pipeline **{data.pipeline}**, profile **{data.profile}**, run directory `{data.run_dir}`."
    ]
    if data.profile == "cpu":
        lines.append(CPU_NOTE)
    if data.description:
        lines.append(data.description)
    lines += list(data.notes)
    if data.results or data.heldout:
        lines.append(f"Differences between policies: {INTERVAL_NOTE}")
    return lines


def render_markdown(data: ReportData, map_dir: str = "") -> str:
    """The report as Markdown; maps are linked as files relative to the report."""
    out = [f"# elicit-jax report: {data.pipeline} ({data.profile} profile)", ""]
    out += [line + "\n" for line in _intro(data)]
    out += markdown_section(data.findings)
    for title, content in _sections(data):
        out += [f"## {title}", ""]
        if isinstance(content, tuple) and content and content[0] == "code":
            out += ["```", content[1].rstrip(), "```", ""]
        elif isinstance(content, list):
            for caption, png in content:
                out += [f"![{caption}]({map_dir}{Path(png).name})", "", f"*{caption}*", ""]
        else:
            out += [_md_table(content), ""]
    return "\n".join(out)


_CSS = (
    "body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;"
    "color:#222}table{border-collapse:collapse;margin:1em 0}th,td{border:1px solid #ccc;"
    "padding:4px 8px;text-align:left}th{background:#f3f3f3}pre{background:#f7f7f7;padding:1em;"
    "overflow-x:auto;font-size:12px}.note{background:#fff3cd;padding:.6em 1em;border-radius:4px}"
    "img{max-width:100%}.findings{border-left:4px solid #4a7;padding-left:1em}"
)


def _html_inline(text: str) -> str:
    out, parts = [], html.escape(text).split("**")
    for i, part in enumerate(parts):
        out.append(f"<b>{part}</b>" if i % 2 else part)
    return "".join(out).replace("`", "")


def render_html(data: ReportData) -> str:
    """The report as one self-contained HTML page (maps inlined as base64 PNG)."""
    esc = html.escape
    body = [f"<h1>elicit-jax report: {esc(data.pipeline)} ({esc(data.profile)} profile)</h1>"]
    for line in _intro(data):
        cls = ' class="note"' if line == CPU_NOTE else ""
        body.append(f"<p{cls}>{_html_inline(line)}</p>")
    body.append(html_section(data.findings))
    for title, content in _sections(data):
        body.append(f"<h2>{esc(title)}</h2>")
        if isinstance(content, tuple) and content and content[0] == "code":
            body.append(f"<details><summary>show</summary><pre>{esc(content[1])}</pre></details>")
        elif isinstance(content, list):
            for caption, png in content:
                b64 = base64.b64encode(Path(png).read_bytes()).decode()
                body.append(
                    f'<figure><img alt="{esc(caption)}" src="data:image/png;base64,'
                    f'{b64}"><figcaption>{esc(caption)}</figcaption></figure>'
                )
        else:
            header, rows = content
            head = "".join(f"<th>{esc(h)}</th>" for h in header)
            trs = "".join("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in r) + "</tr>" for r in rows)
            body.append(f"<table><thead><tr>{head}</tr></thead><tbody>{trs}</tbody></table>")
    return (
        '<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
        f"<title>elicit-jax report: {esc(data.pipeline)}</title><style>{_CSS}</style></head>"
        f"<body>{''.join(body)}</body></html>\n"
    )


def write_report(data: ReportData, out_dir: str | Path) -> tuple[Path, Path]:
    """Atomically write ``out_dir/`` with ``report.md``, ``report.html``, ``maps/*.png`` and
    ``artifact.json``; returns the Markdown and HTML paths."""
    from elicit_jax.artifact import make_header
    from elicit_jax.pipeline.figures import sensitivity_figure

    out_dir = Path(out_dir)
    with atomic_path(out_dir) as tmp:
        (tmp / "maps").mkdir(parents=True)
        for _, png in data.maps:
            (tmp / "maps" / Path(png).name).write_bytes(Path(png).read_bytes())
        figures = sensitivity_figure(data, tmp / "maps" / "lambda-sensitivity.png")
        data = dataclasses.replace(data, figures=tuple(figures))
        (tmp / "report.md").write_text(render_markdown(data, map_dir="maps/"))
        (tmp / "report.html").write_text(render_html(data))
        findings = write_beside(data.findings, tmp)
        header = make_header(
            "pipeline-report",
            1,
            config={"pipeline": data.pipeline, "profile": data.profile},
            n_results=len(data.results),
            files=["report.md", "report.html", *([findings["file"]] if findings else [])],
            **({"findings": findings} if findings else {}),
        )
        (tmp / "artifact.json").write_text(dumps(header) + "\n")
    return out_dir / "report.md", out_dir / "report.html"
