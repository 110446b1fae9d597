"""Markdown and self-contained HTML: the one renderer of reports, session pages and maps.

A document is a heading and ``(title, content)`` blocks. Content is a table ``(header, rows)``,
a paragraph (a ``str``), a code block ``("code", text)`` or a list of figures, each shown by
the caller's ``figure(title, item)`` (a report links its PNGs from Markdown and inlines them
in HTML). :func:`html_page` wraps a body in a complete page with an inline stylesheet and no
external asset; :func:`figure_png` and :func:`img_tag` put a matplotlib figure inline.

The study reports (:mod:`elicit_jax.pipeline.render`), the session pages and report
(:mod:`elicit_jax.elicit.pages`, :mod:`elicit_jax.elicit.report`) and the interactive map
(:mod:`elicit_jax.compat.maps`) all render through here; each keeps only its own content.

Example:
    >>> md_table(["a", "b"], [["1", "x|y"]])
    '| a | b |\\n|---|---|\\n| 1 | x\\\\|y |'
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Callable, Iterable, Sequence
from typing import Any

Block = tuple[str, Any]
FigureRenderer = Callable[[str, Any], list[str]]

CSS = (
    "body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;"
    "color:#222}table{border-collapse:collapse;margin:1em 0}th,td{border:1px solid #ccc;"
    "padding:4px 8px;text-align:left}th{background:#f3f3f3}pre{background:#f7f7f7;padding:1em;"
    "overflow-x:auto;font-size:12px}.note{background:#fff3cd;padding:.6em 1em;border-radius:4px}"
    "img{max-width:100%}"
)


def _no_figures(title: str, item: Any) -> list[str]:
    raise TypeError(f"block '{title}' holds figures but no figure renderer was given")


def html_page(title: str, body: str, css: str = CSS) -> str:
    """A complete self-contained HTML document: ``title`` (escaped), the inline stylesheet
    ``css`` and ``body`` (already HTML)."""
    return (
        '<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
        f"<title>{html.escape(title)}</title><style>{css}</style></head>"
        f"<body>{body}</body></html>\n"
    )


def html_inline(text: str) -> str:
    """Escape ``text`` for HTML, turning ``**bold**`` into ``<b>`` and dropping backticks."""
    out, parts = [], html.escape(text).split("**")
    for i, part in enumerate(parts):
        out.append(f"<b>{part}</b>" if i % 2 else part)
    return "".join(out).replace("`", "")


def md_table(header: Sequence[Any], rows: Iterable[Sequence[Any]]) -> str:
    """A Markdown pipe table; ``|`` inside cells is escaped."""
    cells = [[str(c).replace("|", "\\|") for c in r] for r in [header, *rows]]
    lines = ["| " + " | ".join(cells[0]) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in cells[1:]])


def html_table(header: Sequence[Any], rows: Iterable[Sequence[Any]]) -> str:
    """An HTML table of escaped cells."""
    esc = html.escape
    head = "".join(f"<th>{esc(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{esc(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def html_code(text: str, summary: str = "show") -> str:
    """Preformatted ``text`` folded under ``summary`` (both escaped)."""
    esc = html.escape
    return f"<details><summary>{esc(summary)}</summary><pre>{esc(text)}</pre></details>"


def figure_png(fig: Any, dpi: int = 90) -> bytes:
    """PNG bytes of a matplotlib ``Figure`` (drawn on its own Agg canvas: no global backend)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return buf.getvalue()


def img_tag(png: bytes, alt: str) -> str:
    """An ``<img>`` with the PNG inlined as base64 (``alt`` escaped)."""
    b64 = base64.b64encode(png).decode()
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{b64}">'


def html_figure(png: bytes, alt: str, caption: str | None = None) -> str:
    """A ``<figure>`` of an inlined PNG, with an escaped caption if given."""
    cap = "" if caption is None else f"<figcaption>{html.escape(caption)}</figcaption>"
    return f"<figure>{img_tag(png, alt)}{cap}</figure>"


def is_code(content: Any) -> bool:
    """Whether a block's content is a code block ``("code", text)``."""
    return isinstance(content, tuple) and bool(content) and content[0] == "code"


def markdown_block(title: str, content: Any, figure: FigureRenderer = _no_figures) -> list[str]:
    """The lines of one block: ``## title``, then its content (see the module docstring)."""
    out = [f"## {title}", ""]
    if is_code(content):
        return [*out, "```", content[1].rstrip(), "```", ""]
    if isinstance(content, str):
        return [*out, content, ""]
    if isinstance(content, list):
        return out + [line for item in content for line in figure(title, item)]
    return [*out, md_table(*content), ""]


def html_block(title: str, content: Any, figure: FigureRenderer = _no_figures) -> list[str]:
    """The HTML pieces of one block: an ``<h2>`` title, then its content."""
    out = [f"<h2>{html.escape(title)}</h2>"]
    if is_code(content):
        return [*out, html_code(content[1])]
    if isinstance(content, str):
        return [*out, f"<p>{html.escape(content)}</p>"]
    if isinstance(content, list):
        return out + [piece for item in content for piece in figure(title, item)]
    return [*out, html_table(*content)]


def markdown_blocks(blocks: Sequence[Block], figure: FigureRenderer = _no_figures) -> list[str]:
    """The lines of every block, in order."""
    return [line for title, content in blocks for line in markdown_block(title, content, figure)]


def html_blocks(blocks: Sequence[Block], figure: FigureRenderer = _no_figures) -> list[str]:
    """The HTML pieces of every block, in order."""
    return [piece for title, content in blocks for piece in html_block(title, content, figure)]
