"""The one report path of every study kind (a filtering or models study's report, an
elicitation study's): :func:`write_report` writes the report a study kind's
:class:`ReportLayout` describes (its tables, figures, intro and raw results). What every
report shares is here: its first lines (provenance, seeds, the run, the CPU note), the
findings, its closing blocks (the definition, the stage configs, the versions) and its folder
(``report.md``, ``report.html``, the raw results, the figures and ``artifact.json``, written
atomically).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from elicit_jax.artifact import (
    atomic_path,
    dumps,
    make_header,
    provenance_line,
    read_header,
    refuse_foreign_files,
)
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.evidence import DATA_FILE, ROLLOUTS_FILE, write_rollouts_table
from elicit_jax.pipeline.findings import write_beside
from elicit_jax.pipeline.render import html_document, markdown_document
from elicit_jax.pipeline.report_rows import RunReport
from elicit_jax.render import FigureRenderer

CPU_NOTE = (
    "**CPU profile**: network sizes and epochs are shrunk to fit a 2-core machine "
    "(sizes below); the numbers are not the paper's setting."
)
RAW_FILES = (ROLLOUTS_FILE, DATA_FILE)
"""The raw results a report folder keeps, so that it can be rebuilt."""
REPORT_KINDS = ("pipeline-report", "study-report", "session-report")
"""The artifact kinds of report folders (a pipeline's, a study's, a session's)."""
_REPORT_FIGURE = re.compile(r"^((maps|figures)/([^/]+\.(png|svg))?|session\.png)$")
"""The figures a report folder holds besides the files its header lists (and their folders,
empty when there is nothing to draw)."""


def check_report_folder(folder: str | Path) -> None:
    """Refuse to replace ``folder`` unless it is missing, empty, or a report folder holding
    only what a report writes (its header's ``files``, ``artifact.json``, its figures): a
    folder of the user's, or a report with the user's files added, is never replaced.

    Raises:
      ElicitError: naming the folder (and the files in the way).
    """
    folder = Path(folder)
    if not (folder.exists() or folder.is_symlink()):
        return
    if not folder.is_dir():
        raise ElicitError("is a file, not a report folder; choose another output", folder)
    if not any(folder.iterdir()):
        return
    try:
        header = read_header(folder)
    except ElicitError:
        header = {}
    if header.get("kind") not in REPORT_KINDS:
        raise ElicitError(
            "is an existing directory holding no report written by elicit-jax; it is never "
            "replaced: move it away, or choose another output",
            folder,
        )
    listed = {"artifact.json", *header.get("files", [])}
    refuse_foreign_files(
        folder, lambda rel: rel in listed or bool(_REPORT_FIGURE.match(rel)), "a report"
    )


def training_seeds(data: RunReport) -> list[int]:
    """The training seeds of a report's results (held-out ones included)."""
    return sorted({r.seed for r in (*data.results, *getattr(data, "heldout", ()))})


def provenance_blocks(data: Any, definition_title: str) -> list[tuple[str, Any]]:
    """The closing blocks every report ends with: the definition's text, each stage's config
    and the library versions (``data`` has ``spec_text``, ``configs`` and ``versions``)."""
    return [
        (definition_title, ("code", data.spec_text or "(not recorded)")),
        ("Stage configs", ("code", dumps(dict(data.configs)))),
        ("Library versions", ("code", dumps(dict(data.versions)))),
    ]


def provenance_intro(data: RunReport) -> list[str]:
    """The first lines of every study report: where its numbers came from (the run's code
    commit, versions and command line; the seeds), and how to rebuild it from its folder."""
    seeds = training_seeds(data)
    evals = sorted(
        {s for r in (*data.results, *getattr(data, "heldout", ())) for s in r.eval_seeds}
    )
    raw = (
        f"Raw results: `{ROLLOUTS_FILE}` (one row per rollout) and `{DATA_FILE}` beside this "
        "report; `elicit-jax report --rebuild <this folder>` recomputes every table, interval "
        "and figure from them."
        if data.raw_results
        else "Raw results: not kept beside this report, so it cannot be rebuilt from its folder."
    )
    return [
        provenance_line(data.provenance),
        f"Seeds: training {seeds or '–'}, evaluation {evals or '–'}. {raw}",
    ]


def intro_lines(data: RunReport, noun: str) -> list[str]:
    """The first lines of a report: provenance and seeds (:func:`provenance_intro`), what
    ran (``noun``: ``Pipeline``, ``Study``) under which profile and where, the CPU note of the
    ``cpu`` profile and the definition's description."""
    lines = provenance_intro(data)
    lines.append(
        f"{noun} **{data.pipeline}**, profile **{data.profile}**, run directory `{data.run_dir}`."
    )
    if data.profile == "cpu":
        lines.append(CPU_NOTE)
    if data.description:
        lines.append(data.description)
    return lines


@dataclasses.dataclass(frozen=True)
class ReportLayout:
    """What a study kind's report is made of: everything :func:`write_report` asks of it.

    Attributes:
      kind: the report folder's artifact kind (``pipeline-report``, ``study-report``).
      title: the page's title before the study's name (``elicit-jax report``).
      definition: the title of the closing block that holds the definition's text.
      notes: intro lines highlighted on the HTML page besides :data:`CPU_NOTE`.
      intro: ``data -> lines``: the paragraphs before the findings.
      sections: ``(data, folder) -> blocks``: its tables and figures, in order (``folder``:
        the report folder being written, holding what ``draw`` drew).
      draw: ``(folder, data) -> (data, files)``: writes its figures into the folder being
        written, returns ``data`` as rendered and the figure files to list in its header.
      figures: ``folder -> (markdown, HTML)``: how each renderer shows one of its figures.
      to_json: ``data -> header``: its ``report-data.json`` (everything but the rollouts).
      fields: ``data -> {field: value}``: further fields of the folder's header.
      heading: ``data -> text``: what the heading adds after the profile (``; sizes default,
        paper``), nothing by default.
    """

    kind: str
    title: str
    definition: str
    notes: tuple[str, ...]
    intro: Callable[[Any], list[str]]
    sections: Callable[[Any, Path], list[tuple[str, Any]]]
    draw: Callable[[Path, Any], tuple[Any, list[str]]]
    figures: Callable[[Path], tuple[FigureRenderer, FigureRenderer]]
    to_json: Callable[[Any], dict[str, Any]]
    fields: Callable[[Any], dict[str, Any]] = lambda _: {}
    heading: Callable[[Any], str] = lambda _: ""


def render_report(layout: ReportLayout, data: RunReport, folder: Path) -> tuple[str, str]:
    """A report as Markdown and as one self-contained HTML page: heading, intro, findings,
    the layout's sections and the closing blocks every report ends with."""
    heading = f"{layout.title}: {data.pipeline} ({data.profile} profile{layout.heading(data)})"
    blocks = layout.sections(data, folder) + provenance_blocks(data, layout.definition)
    intro = layout.intro(data)
    markdown_figure, html_figure = layout.figures(folder)
    markdown = markdown_document(heading, intro, data.findings, blocks, markdown_figure)
    page = html_document(
        f"{layout.title}: {data.pipeline}",
        heading,
        intro,
        [CPU_NOTE, *layout.notes],
        data.findings,
        blocks,
        html_figure,
    )
    return markdown, page


def write_report(
    layout: ReportLayout, data: RunReport, out_dir: str | Path, rebuilt_from: Path | None = None
) -> tuple[Path, Path]:
    """Atomically write the report folder of any study kind, as its ``layout`` says;
    returns the Markdown and HTML paths.

    The folder holds ``report.md``, ``report.html``, the raw results (``rollouts.parquet``
    and ``report-data.json``, when ``data.rollouts`` is kept), the figures, the findings and
    ``artifact.json``.

    Args:
      layout: the study kind's report.
      data: what the report shows.
      out_dir: the report folder.
      rebuilt_from: a report folder being rebuilt: its raw-result files are copied as they
        are (byte for byte) instead of written anew.
    """
    out_dir = Path(out_dir)
    check_report_folder(out_dir)
    with atomic_path(out_dir) as tmp:
        tmp.mkdir(parents=True)
        if rebuilt_from is not None:
            for name in RAW_FILES:
                (tmp / name).write_bytes((rebuilt_from / name).read_bytes())
        elif data.rollouts is not None:
            write_rollouts_table(tmp / ROLLOUTS_FILE, data.rollouts, data.pipeline, data.profile)
            (tmp / DATA_FILE).write_text(dumps(layout.to_json(data)) + "\n")
        kept = [n for n in RAW_FILES if (tmp / n).is_file()]
        data, drawn = layout.draw(tmp, dataclasses.replace(data, raw_results=bool(kept)))
        markdown, html = render_report(layout, data, tmp)
        (tmp / "report.md").write_text(markdown)
        (tmp / "report.html").write_text(html)
        findings = write_beside(data.findings, tmp)
        seeds = training_seeds(data)
        header = make_header(
            layout.kind,
            1,
            config={"pipeline": data.pipeline, "profile": data.profile},
            inputs={name: tmp / name for name in kept},
            seed=seeds[0] if seeds else None,
            training_seeds=seeds,
            run=dict(data.provenance),
            **({"rebuilt_from": str(rebuilt_from)} if rebuilt_from is not None else {}),
            n_results=len(data.results),
            files=["report.md", "report.html", *kept, *drawn]
            + ([findings["file"]] if findings else []),
            **({"findings": findings} if findings else {}),
            **layout.fields(data),
        )
        for entry in header["inputs"].values():
            entry["path"] = Path(entry["path"]).name
        (tmp / "artifact.json").write_text(dumps(header) + "\n")
    return out_dir / "report.md", out_dir / "report.html"
