"""Markdown and self-contained HTML for reports made of titled blocks.

A report is a heading, intro paragraphs, optional findings (:mod:`elicit_jax.pipeline.findings`)
and ``(title, content)`` blocks, where content is a table ``(header, rows)``, a code block
``("code", text)`` or a list of figures. Both report kinds (filtering pipelines, elicitation
studies) render through here; each passes how one of its figures is shown.
"""

from __future__ import annotations

import html
from collections.abc import Callable, Iterable, Sequence
from typing import Any

from elicit_jax.pipeline.findings import Findings, html_section, markdown_section
from elicit_jax.pipeline.tables import Table

Block = tuple[str, Any]
FigureRenderer = Callable[[str, Any], list[str]]

CSS = (
    "body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;"
    "color:#222}table{border-collapse:collapse;margin:1em 0}th,td{border:1px solid #ccc;"
    "padding:4px 8px;text-align:left}th{background:#f3f3f3}pre{background:#f7f7f7;padding:1em;"
    "overflow-x:auto;font-size:12px}.note{background:#fff3cd;padding:.6em 1em;border-radius:4px}"
    "img{max-width:100%}.findings{border-left:4px solid #4a7;padding-left:1em}"
)


def md_table(table: Table) -> str:
    """A pipe table; ``|`` inside cells is escaped."""
    header, rows = table
    esc = [[str(c).replace("|", "\\|") for c in row] for row in [header, *rows]]
    lines = ["| " + " | ".join(esc[0]) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in esc[1:]]
    return "\n".join(lines)


def html_inline(text: str) -> str:
    """Escape ``text`` for HTML, turning ``**bold**`` into ``<b>`` and dropping backticks."""
    out, parts = [], html.escape(text).split("**")
    for i, part in enumerate(parts):
        out.append(f"<b>{part}</b>" if i % 2 else part)
    return "".join(out).replace("`", "")


def _is_code(content: Any) -> bool:
    return isinstance(content, tuple) and bool(content) and content[0] == "code"


def markdown_document(
    heading: str,
    intro: Iterable[str],
    findings: Findings | None,
    blocks: Sequence[Block],
    figure: FigureRenderer,
) -> str:
    """The report as Markdown; ``figure(title, item)`` gives a figure's lines."""
    out = [f"# {heading}", ""]
    out += [line + "\n" for line in intro]
    out += markdown_section(findings)
    for title, content in blocks:
        out += [f"## {title}", ""]
        if _is_code(content):
            out += ["```", content[1].rstrip(), "```", ""]
        elif isinstance(content, list):
            for item in content:
                out += figure(title, item)
        else:
            out += [md_table(content), ""]
    return "\n".join(out)


def html_document(
    title: str,
    heading: str,
    intro: Iterable[str],
    notes: Iterable[str],
    findings: Findings | None,
    blocks: Sequence[Block],
    figure: FigureRenderer,
) -> str:
    """The report as one HTML page without external assets; intro lines that are in
    ``notes`` are highlighted, and ``figure(title, item)`` gives a figure's HTML."""
    esc = html.escape
    notes = set(notes)
    body = [f"<h1>{esc(heading)}</h1>"]
    for line in intro:
        cls = ' class="note"' if line in notes else ""
        body.append(f"<p{cls}>{html_inline(line)}</p>")
    body.append(html_section(findings))
    for block_title, content in blocks:
        body.append(f"<h2>{esc(block_title)}</h2>")
        if _is_code(content):
            body.append(f"<details><summary>show</summary><pre>{esc(content[1])}</pre></details>")
        elif isinstance(content, list):
            for item in content:
                body += figure(block_title, item)
        else:
            header, rows = content
            head = "".join(f"<th>{esc(h)}</th>" for h in header)
            trs = "".join("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in r) + "</tr>" for r in rows)
            body.append(f"<table><thead><tr>{head}</tr></thead><tbody>{trs}</tbody></table>")
    return (
        '<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
        f"<title>{esc(title)}</title><style>{CSS}</style></head>"
        f"<body>{''.join(body)}</body></html>\n"
    )
