"""Markdown and self-contained HTML for study reports: a heading, intro paragraphs, the
findings (:mod:`elicit_jax.pipeline.findings`) and titled blocks.

Both report kinds (filtering pipelines, elicitation studies) render through here; each passes
how one of its figures is shown. The blocks, tables, figures and page shell are the package's
one renderer (:mod:`elicit_jax.render`); what is a report's own is the document's order, the
highlighted notes among the intro lines and the findings section.
"""

from __future__ import annotations

import html
from collections.abc import Iterable, Sequence

from elicit_jax.pipeline.findings import Findings, html_section, markdown_section
from elicit_jax.render import (
    CSS,
    Block,
    FigureRenderer,
    html_blocks,
    html_inline,
    html_page,
    markdown_blocks,
)

REPORT_CSS = CSS + ".findings{border-left:4px solid #4a7;padding-left:1em}"


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
    out += markdown_blocks(blocks, figure)
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
    notes = set(notes)
    body = [f"<h1>{html.escape(heading)}</h1>"]
    for line in intro:
        cls = ' class="note"' if line in notes else ""
        body.append(f"<p{cls}>{html_inline(line)}</p>")
    body.append(html_section(findings))
    body += html_blocks(blocks, figure)
    return html_page(title, "".join(body), REPORT_CSS)
