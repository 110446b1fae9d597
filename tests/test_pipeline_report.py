"""Report rendering: the paper's table layout, mean (std) over seeds, self-contained HTML."""

from __future__ import annotations

import base64
import hashlib
import re
from pathlib import Path

import pytest

from elicit_jax.artifact import read_header
from elicit_jax.pipeline import report_folder
from elicit_jax.pipeline.report import LAYOUT
from elicit_jax.pipeline.report_folder import CPU_NOTE, render_report
from elicit_jax.pipeline.tables import (
    FilterRow,
    LengthRow,
    ReportData,
    ResultRow,
    ThresholdRow,
    mean_std,
    models_table,
    results_tables,
)


def render_markdown(d: ReportData) -> str:
    """The filtering report's Markdown (its figures are files of the run: no folder read)."""
    return render_report(LAYOUT, d, Path())[0]


def render_html(d: ReportData) -> str:
    return render_report(LAYOUT, d, Path())[1]


def write_report(d: ReportData, out: Path) -> tuple[Path, Path]:
    return report_folder.write_report(LAYOUT, d, out)


# The smallest valid PNG (1×1, transparent).
PNG = base64.b64decode(
    "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mNkYPhfDwAChwGA60e6kgAAAABJRU5ErkJggg=="
)


def row(method, op, seed, success, model="mlp"):
    return ResultRow("square-nut", model, method, op, seed, success, 100.0 + seed, 50, "best")


def data(tmp_path, profile="cpu") -> ReportData:
    png = tmp_path / "square-nut-mlp.png"
    png.write_bytes(PNG)
    results = [row("base", None, s, v) for s, v in enumerate((0.40, 0.36, 0.38))]
    results += [row("naive", "same-style", s, v) for s, v in enumerate((0.50, 0.56, 0.56))]
    results += [row("filtered", "same-style", s, v) for s, v in enumerate((0.52, 0.50, 0.54))]
    results += [row("naive", "conflict-ring", s, v) for s, v in enumerate((0.20, 0.30, 0.28))]
    results += [row("filtered", "conflict-ring", s, v) for s, v in enumerate((0.36, 0.40, 0.38))]
    results += [row("base", None, 0, 0.1, model="mdn"), row("naive", "same-style", 0, 0.2, "mdn")]
    return ReportData(
        pipeline="filtering",
        profile=profile,
        description="A study.",
        run_dir=str(tmp_path),
        spec_text="# spec\n[pipeline]\nname = 'filtering'\n",
        results=tuple(results),
        thresholds=(
            ThresholdRow(
                "square-nut",
                "mlp",
                0.41,
                0.052,
                "held-out base",
                "conflict-flip x3",
                {
                    "balanced_accuracy": 1.0,
                    "margin": 0.125,
                    "loo_accuracy": 0.875,
                    "per_operator": {
                        "conflict-flip": {
                            "pairs": 300,
                            "incompatible_pairs": 45,
                            "episodes": 3,
                            "rejected_episodes": 3,
                        }
                    },
                },
            ),
        ),
        lengths=(LengthRow("square-nut", "base", "base", 50, 87.25, 4.5),),
        filters=(FilterRow("square-nut", "mlp", "filtered", "conflict-ring", 750, 1000, 10, 10),),
        maps=(("square-nut, mlp: compatibility map per operator", str(png)),),
        configs={"train": {"train/x": {"epochs": 100}}},
        versions={"jax": "0.10.2"},
    )


def test_mean_std_over_seeds_by_hand():
    # 100 × (0.40, 0.36, 0.38) = 40, 36, 38: mean 38; sample var (ddof 1) = (4 + 4 + 0) / 2 = 4
    # → std 2.0
    assert mean_std([0.40, 0.36, 0.38]) == "38.0 (2.0)"
    assert mean_std([0.5]) == "50.0 (–)"
    assert mean_std([]) == "–"


def test_results_table_has_paper_layout(tmp_path):
    (title, (header, rows)), _ = results_tables(data(tmp_path))
    assert title.startswith("square-nut — mlp")
    assert header == ["operator", "Naive", "M-Filtered"]
    assert rows[0][0] == "base only: 38.0 (2.0)"
    # same-style naive: 50, 56, 56 → mean 54, var = (16 + 4 + 4) / 2 = 12 → std 3.46;
    # filtered: 52, 50, 54 → mean 52, var = (0 + 4 + 4) / 2 = 4 → std 2.0
    assert rows[1] == ["same-style", "54.0 (3.5)", "52.0 (2.0)"]
    # conflict-ring naive: 20, 30, 28 → mean 26, var = (36 + 16 + 4) / 2 = 28 → std 5.29
    assert rows[2] == ["conflict-ring", "26.0 (5.3)", "38.0 (2.0)"]
    ((_, (mheader, mrows)),) = models_table(data(tmp_path))
    assert mheader == ["", "mlp", "mdn"]
    assert mrows[0] == ["Base (D_base only)", "38.0 (2.0)", "10.0 (–)"]
    assert mrows[1] == ["Naive + same-style", "54.0 (3.5)", "20.0 (–)"]


def test_markdown_and_html_carry_every_section(tmp_path):
    d = data(tmp_path)
    md = render_markdown(d)
    for text in (
        CPU_NOTE,
        "| same-style | 54.0 (3.5) | 52.0 (2.0) |",
        "0.41",
        "0.052",
        "750/1000 (75.0%)",
        "87.2 (4.5)",
        "![square-nut, mlp",
        "(maps/square-nut-mlp.png)",
        "name = 'filtering'",
        "| square-nut | mlp | conflict-flip | 300 | 45 (15.0%) | 3/3 |",
        '"jax": "0.10.2"',
        "held-out base",
    ):
        assert text in md, text
    page = render_html(d)
    assert "data:image/png;base64," + base64.b64encode(PNG).decode() in page
    assert not re.search(r"""(src|href)=["'](https?:|//|/)""", page)
    assert "<script" not in page and "<link" not in page
    assert "<b>CPU profile</b>" in page
    assert "54.0 (3.5)" in page and "&lt;" not in md


def test_paper_profile_has_no_cpu_note(tmp_path):
    d = data(tmp_path, profile="paper")
    assert CPU_NOTE not in render_markdown(d) and "CPU profile" not in render_html(d)


def test_write_report_is_a_self_describing_directory(tmp_path):
    md, page = write_report(data(tmp_path), tmp_path / "report")
    assert md.read_text().startswith("# elicit-jax report: filtering (cpu profile)")
    assert (tmp_path / "report" / "maps" / "square-nut-mlp.png").read_bytes() == PNG
    header = read_header(tmp_path / "report")
    assert header["kind"] == "pipeline-report" and header["n_results"] == 17
    assert page.exists()


@pytest.mark.parametrize("bad", ["a|b"])
def test_markdown_escapes_pipes(tmp_path, bad):
    d = data(tmp_path)
    d = type(d)(**{**d.__dict__, "results": (row("naive", bad, 0, 0.5), *d.results)})
    assert "a\\|b" in render_markdown(d)


def test_report_of_a_directory_that_is_not_a_run_fails_in_one_line(tmp_path):
    from elicit_jax.errors import ElicitError
    from elicit_jax.pipeline.run import render_run_report

    with pytest.raises(ElicitError, match=r"not a pipeline run directory \(no run.json\)"):
        render_run_report(tmp_path)


FINDINGS = """### What the table shows

The filter **helps** the `conflict-ring` operator: +12 points [see the
report](report.md).

- first point
  continues here
- second point

| a | b |
|---|---|
| 1 | x&y |
"""


def test_findings_html_renders_the_markdown_subset_by_hand():
    from elicit_jax.pipeline.findings import findings_html

    assert findings_html(FINDINGS) == (
        "<h3>What the table shows</h3>"
        "<p>The filter <b>helps</b> the <code>conflict-ring</code> operator: +12 points "
        '<a href="report.md">see the report</a>.</p>'
        "<ul><li>first point continues here</li><li>second point</li></ul>"
        "<table><thead><tr><th>a</th><th>b</th></tr></thead>"
        "<tbody><tr><td>1</td><td>x&amp;y</td></tr></tbody></table>"
    )


def test_findings_come_first_travel_with_the_report_and_survive_a_rebuild(tmp_path):
    from elicit_jax.pipeline.findings import TITLE, read_findings

    source = tmp_path / "notes.md"
    source.write_text(FINDINGS)
    d = data(tmp_path)
    out = tmp_path / "report"
    write_report(type(d)(**{**d.__dict__, "findings": read_findings(source)}), out)
    md = (out / "report.md").read_text()
    assert md.index(f"## {TITLE}") < md.index("## square-nut — mlp")
    assert "- first point\n  continues here" in md
    assert "<li>first point continues here</li>" in (out / "report.html").read_text()
    assert (out / "findings.md").read_text() == FINDINGS
    header = read_header(out)
    assert header["findings"]["source"] == "notes.md"
    assert header["findings"]["sha256"] == hashlib.sha256(FINDINGS.encode()).hexdigest()
    assert "findings.md" in header["files"]
    # Rebuilding into the same directory from the copy inside it keeps the text.
    write_report(type(d)(**{**d.__dict__, "findings": read_findings(out / "findings.md")}), out)
    assert (out / "findings.md").read_text() == FINDINGS
    write_report(d, out)
    assert not (out / "findings.md").exists() and TITLE not in (out / "report.md").read_text()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "findings file not found"),
        (b"  \n\n", "findings file is empty"),
        (b"ok \xff\xfe", "not UTF-8 text"),
        (b"# Title\n\ntext", "top-level '# ' heading"),
    ],
)
def test_bad_findings_file_is_one_line_error_and_writes_nothing(tmp_path, content, message):
    from elicit_jax.errors import ElicitError
    from elicit_jax.pipeline.run import render_run_report

    path = tmp_path / "findings.md"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(ElicitError, match=re.escape(message)) as err:
        render_run_report(tmp_path, tmp_path / "out", findings=path)
    assert str(err.value).startswith(str(path)) and "\n" not in str(err.value)
    assert not (tmp_path / "out").exists()
