"""The authors' reading of a run, carried inside its report.

A report's tables are generated from the run; what they show (which differences are real,
where the shape matches a paper's and why it does not) is written by people. ``elicit-jax
report --findings FILE`` puts such a Markdown file into the report as its first section and
copies it beside ``report.md``, so the reading travels with the numbers and is re-inserted
each time the report is rebuilt. The HTML page renders the small Markdown subset findings
need: paragraphs, ``- `` bullet lists, pipe tables, ``**bold**``, ```code``` and links.
"""

from __future__ import annotations

import dataclasses
import hashlib
import html
import re
from pathlib import Path

from elicit_jax.errors import ElicitError

FINDINGS_FILE = "findings.md"
TITLE = "Findings (the authors' reading of the numbers below)"


@dataclasses.dataclass(frozen=True)
class Findings:
    """A findings text and where it came from.

    Attributes:
      text: the Markdown text, stripped.
      name: the source file's name (no directory: reports are shared).
      sha256: hex digest of the source file's bytes.
    """

    text: str
    name: str
    sha256: str

    def header(self) -> dict[str, str]:
        """The entry a report's ``artifact.json`` records for it."""
        return {"file": FINDINGS_FILE, "source": self.name, "sha256": self.sha256}


def read_findings(path: str | Path) -> Findings:
    """Read and check a findings file.

    Raises:
      ElicitError: the file is missing, not UTF-8, or has no text.
    """
    path = Path(path)
    if not path.is_file():
        raise ElicitError("findings file not found", path)
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8").strip()
    except UnicodeDecodeError as e:
        raise ElicitError(f"findings file is not UTF-8 text (byte {e.start})", path) from e
    if not text:
        raise ElicitError("findings file is empty", path)
    if "\n# " in f"\n{text}":
        raise ElicitError(
            "findings file has a top-level '# ' heading; start headings at '###' (the report "
            "puts the text under its own '## Findings' section)",
            path,
        )
    return Findings(text=text, name=path.name, sha256=hashlib.sha256(raw).hexdigest())


_LINK = re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)")
_CODE = re.compile(r"`([^`]+)`")
_BOLD = re.compile(r"\*\*(.+?)\*\*")
_HEADING = re.compile(r"^(#{3,6})\s+(.*)$")


def _inline(text: str) -> str:
    out = html.escape(text, quote=False)
    out = _CODE.sub(r"<code>\1</code>", out)
    out = _BOLD.sub(r"<b>\1</b>", out)
    return _LINK.sub(lambda m: f'<a href="{html.escape(m[2])}">{m[1]}</a>', out)


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _table(lines: list[str]) -> str:
    rows = [_cells(line) for line in lines if not re.fullmatch(r"[\s|:-]+", line)]
    head = "".join(f"<th>{_inline(c)}</th>" for c in rows[0])
    body = "".join(
        "<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in row) + "</tr>" for row in rows[1:]
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _list(lines: list[str]) -> str:
    items: list[str] = []
    for line in lines:
        if line.lstrip().startswith("- "):
            items.append(line.lstrip()[2:])
        else:
            items[-1] += " " + line.strip()
    return "<ul>" + "".join(f"<li>{_inline(item)}</li>" for item in items) + "</ul>"


def findings_html(text: str) -> str:
    """``text`` (the Markdown subset above) as HTML blocks."""
    out = []
    for block in re.split(r"\n\s*\n", text.strip()):
        lines = block.splitlines()
        heading = _HEADING.match(lines[0])
        if heading:
            level = min(len(heading[1]), 6)
            out.append(f"<h{level}>{_inline(heading[2])}</h{level}>")
            lines = lines[1:]
            if not lines:
                continue
        if lines[0].lstrip().startswith("|"):
            out.append(_table(lines))
        elif lines[0].lstrip().startswith("- "):
            out.append(_list(lines))
        else:
            out.append(f"<p>{_inline(' '.join(line.strip() for line in lines))}</p>")
    return "".join(out)


def markdown_section(findings: Findings | None) -> list[str]:
    """The report's Markdown lines for ``findings`` (none when there are none)."""
    if findings is None:
        return []
    return [f"## {TITLE}", "", findings.text, ""]


def html_section(findings: Findings | None) -> str:
    """The report's HTML for ``findings`` (empty when there are none)."""
    if findings is None:
        return ""
    body = findings_html(findings.text)
    return f'<h2>{html.escape(TITLE)}</h2><div class="findings">{body}</div>'


def write_beside(findings: Findings | None, report_dir: Path) -> dict[str, str]:
    """Copy ``findings`` into ``report_dir`` and return the header entry (``{}`` if none)."""
    if findings is None:
        return {}
    (report_dir / FINDINGS_FILE).write_text(findings.text + "\n")
    return findings.header()
