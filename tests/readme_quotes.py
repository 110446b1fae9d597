"""Check that every number the README (and docs/*.md) quotes from a report is in that report.

A quoted block starts with a marker line naming its source report(s)::

    <!-- from docs/results/filtering-cpu-round-nut/report.md -->
    | table or paragraph quoting the report |

and runs to the next blank line. Decimal numbers (``32.0``, ``−7.2``, ``+20.8``,
``1,393.0``; signs and the Unicode minus normalised) are checked; integers are labels and
counts as often as results, so they are not. In a table, each cell's numbers must appear in
that order, side by side, on one line of one of the named reports (``33.8 (5.4)`` must be a
mean and its std, ``−7.2 [−20.1, +5.7]`` a difference and its interval); in prose, each number
must appear in one of the named reports. Run ``python tests/readme_quotes.py`` from the
repository root to check by hand; the test suite runs it (tests/test_readme_quotes.py).
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

MARKER = re.compile(r"^<!-- from (.+?) -->\s*$")
NUMBER = re.compile(r"(?<![\w.])[-+−]?\d{1,3}(?:,\d{3})*\.\d+|(?<![\w.])[-+−]?\d+\.\d+")


def sequence(text: str) -> list[str]:
    """The decimal numbers of ``text`` in order, normalised (``−`` and ``+`` signs, thousands
    commas; ``-0.0`` is ``0.0``)."""
    out = []
    for token in NUMBER.findall(text):
        token = token.replace("−", "-").replace("+", "").replace(",", "")
        out.append(token.removeprefix("-") if float(token) == 0 else token)
    return out


def numbers(text: str) -> set[str]:
    """The decimal numbers of ``text``, normalised as :func:`sequence`."""
    return set(sequence(text))


def _contains(line: list[str], cell: list[str]) -> bool:
    n = len(cell)
    return any(line[i : i + n] == cell for i in range(len(line) - n + 1))


def missing_quotes(block: str, report_lines: list[list[str]]) -> list[str]:
    """The quoted numbers of ``block`` (tables cell by cell) that the reports do not hold."""
    everything = {x for line in report_lines for x in line}
    missing = []
    for line in block.splitlines():
        if line.lstrip().startswith("|"):
            for cell in line.strip().strip("|").split("|"):
                seq = sequence(cell)
                if seq and not any(_contains(r, seq) for r in report_lines):
                    missing.append(" ".join(seq))
        else:
            missing += [x for x in sequence(line) if x not in everything]
    return missing


def quoted_blocks(text: str) -> list[tuple[int, list[str], str]]:
    """``(line number, source paths, block text)`` of every marked block."""
    lines = text.splitlines()
    blocks = []
    for i, line in enumerate(lines):
        m = MARKER.match(line)
        if not m:
            continue
        body = []
        for follow in lines[i + 1 :]:
            if not follow.strip():
                break
            body.append(follow)
        sources = [s.strip() for s in m.group(1).split(",") if s.strip()]
        blocks.append((i + 1, sources, "\n".join(body)))
    return blocks


def check_file(path: Path, root: Path) -> list[str]:
    """Problems of one Markdown file's quoted blocks (empty: every quoted number found)."""
    problems = []
    for line, sources, block in quoted_blocks(path.read_text()):
        where = f"{path.relative_to(root)}:{line}"
        if not block:
            problems.append(f"{where}: the marker quotes nothing (no text below it)")
            continue
        report_lines: list[list[str]] = []
        for source in sources:
            report = root / source
            if not report.is_file():
                problems.append(f"{where}: quoted report {source} does not exist")
                continue
            report_lines += [sequence(line) for line in report.read_text().splitlines()]
        missing = missing_quotes(block, report_lines)
        if missing:
            problems.append(
                f"{where}: {', '.join(missing)} not in {', '.join(sources)} (quoted wrongly, "
                "or the report changed: update the quote from the report)"
            )
    return problems


def check_repository(root: Path) -> tuple[int, list[str]]:
    """(number of quoted blocks, problems) over README.md and docs/**/*.md."""
    files = [root / "README.md", *sorted((root / "docs").rglob("*.md"))]
    files = [f for f in files if f.is_file() and "results/" not in str(f.relative_to(root))]
    n = sum(len(quoted_blocks(f.read_text())) for f in files)
    return n, [p for f in files for p in check_file(f, root)]


if __name__ == "__main__":
    count, found_problems = check_repository(Path.cwd())
    for problem in found_problems:
        print(problem)
    print(f"{count} quoted block(s), {len(found_problems)} problem(s)")
    sys.exit(1 if found_problems else 0)
