"""The README quotes reports only with numbers the reports hold (tests/readme_quotes.py), and
the check fails when a quoted number is edited."""

from __future__ import annotations

import shutil
from pathlib import Path

from readme_quotes import check_file, check_repository, numbers

ROOT = Path(__file__).resolve().parents[1]


def test_numbers_are_normalised():
    assert numbers("−7.2 [−20.1, +5.7] * 1,393.5 and 50 demos, 0.0 or -0.0") == {
        "-7.2", "-20.1", "5.7", "1393.5", "0.0",
    }  # fmt: skip


def test_every_quoted_number_is_in_its_report():
    count, problems = check_repository(ROOT)
    assert problems == []
    assert count >= 2  # the filtering tables and HG-DAgger's


def test_an_edited_quote_fails(tmp_path):
    (tmp_path / "docs").mkdir()
    shutil.copytree(ROOT / "docs" / "results", tmp_path / "docs" / "results")
    shutil.copytree(ROOT / "benchmarks" / "results", tmp_path / "benchmarks" / "results")
    readme = (ROOT / "README.md").read_text()
    (tmp_path / "README.md").write_text(readme)
    assert check_file(tmp_path / "README.md", tmp_path) == []
    # robosuite-square's M-filtered cell, 28.7, edited to 27.8
    assert "| M-Filtered (pairs, forced fit) | 28.7 (3.1) |" in readme
    edited = readme.replace(
        "| M-Filtered (pairs, forced fit) | 28.7 (3.1) |",
        "| M-Filtered (pairs, forced fit) | 27.8 (3.1) |",
    )
    (tmp_path / "README.md").write_text(edited)
    (problem,) = check_file(tmp_path / "README.md", tmp_path)
    assert "27.8 3.1 not in docs/results/filtering-cpu-robosuite-square/report.md" in problem
    # a quote naming a report that is not there
    (tmp_path / "README.md").write_text("<!-- from docs/results/nope/report.md -->\n| 1.5 |\n")
    assert "does not exist" in check_file(tmp_path / "README.md", tmp_path)[0]
