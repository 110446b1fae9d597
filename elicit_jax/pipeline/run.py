"""Run a pipeline definition end to end: plan the graph, run it, report, summarise.

This is the library function behind ``elicit-jax pipeline run`` and ``elicit-jax quickstart``.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from elicit_jax.artifact import make_header, write_json
from elicit_jax.pipeline.gather import MANIFEST, MANIFEST_KIND
from elicit_jax.pipeline.graph import Graph
from elicit_jax.pipeline.runner import RunResult, StageFn, print_summary, run_graph, run_lock
from elicit_jax.pipeline.spec import PipelineSpec

REPORT_DIR = "report"


@dataclasses.dataclass(frozen=True)
class PipelineRunConfig:
    """What to run.

    Attributes:
      pipeline: a definition file, or the name of a shipped one (``quickstart``,
        ``filtering``, ``models``, ``elicitation``).
      profile: ``paper`` or ``cpu``; default: the definition's own.
      out: run directory; default ``runs/<name>-<profile>``.
      progress: draw progress bars.
      tasks: run only these of the definition's tasks (default: all); the default run
        directory then ends in their names.
      ray: run the stages as Ray tasks at this address (``local``, ``auto``, ``HOST:PORT``,
        ``ray://HOST:PORT``; see :func:`elicit_jax.pipeline.ray_runner.ray_session`); default
        ``None``: run them one after another in this process.
      sizes: the named sizes to run side by side, comma-separated (``default``, ``paper``:
        :mod:`elicit_jax.pipeline.sizes`); default: the definition's ``[pipeline] sizes``.
    """

    pipeline: str = "quickstart"
    profile: str | None = None
    out: str | None = None
    progress: bool = True
    ray: str | None = None
    tasks: tuple[str, ...] | None = None
    sizes: str | None = None


@dataclasses.dataclass(frozen=True)
class PipelineOutcome:
    """A finished run: where it is, what ran, and its report files."""

    run_dir: Path
    result: RunResult
    report_md: Path
    report_html: Path


def default_run_dir(spec: PipelineSpec, tasks: tuple[str, ...] | None = None) -> Path:
    """``runs/<name>-<profile>``, plus ``-<task>...`` when only some tasks run."""
    suffix = "".join(f"-{t}" for t in tasks or ())
    return Path("runs") / f"{spec.name}-{spec.profile}{suffix}"


def plan_run(config: PipelineRunConfig) -> tuple[Any, Graph, Callable[[], Mapping[str, StageFn]]]:
    """The definition, its stage graph and its stage registry, by the definition's study kind
    (:mod:`elicit_jax.pipeline.study_kinds`: filtering, elicitation)."""
    from elicit_jax.pipeline.study_kinds import plan_definition

    return plan_definition(config.pipeline, config.profile, config.tasks, config.sizes)


def write_manifest(run_dir: Path, spec: PipelineSpec, graph: Graph) -> None:
    """Write ``run.json``: the definition (text, source, profile) and every stage."""
    stages = [
        {
            "id": s.id,
            "kind": s.kind,
            "output": s.output,
            "config": dict(s.config),
            "inputs": dict(s.inputs),
            "seed": s.seed,
        }
        for s in graph
    ]
    header = make_header(
        MANIFEST_KIND,
        1,
        config={
            "pipeline": spec.name,
            "kind": spec.kind,
            "profile": spec.profile,
            "description": spec.description,
            "source": spec.source,
            "spec_text": spec.text,
        },
        stages=stages,
    )
    write_json(run_dir / MANIFEST, header)


def check_run_dir(run_dir: Path) -> None:
    """Refuse a run directory that holds anything but a pipeline run (the rule of ``train
    --out`` and ``elicit -o``): a missing or empty folder starts a run, one with a pipeline's
    ``run.json`` resumes it, anything else is the user's and is never written into. Its
    report folder, replaced at the end of every run, must be a report holding only what a
    report writes (:func:`elicit_jax.pipeline.report_folder.check_report_folder`).

    Raises:
      ElicitError: naming the folder and what is in it.
    """
    from elicit_jax.artifact import foreign_files
    from elicit_jax.errors import ElicitError
    from elicit_jax.pipeline.gather import read_manifest
    from elicit_jax.pipeline.report_folder import check_report_folder

    if not (run_dir.exists() or run_dir.is_symlink()):
        return
    if not run_dir.is_dir():
        raise ElicitError("is a file, not a run directory; choose another --out", run_dir)
    if not any(run_dir.iterdir()):
        return
    try:
        read_manifest(run_dir)
    except ElicitError as e:
        found = foreign_files(run_dir, lambda rel: False)
        shown = ", ".join(found[:4]) + (f" and {len(found) - 4} more" if len(found) > 4 else "")
        raise ElicitError(
            f"holds files not made by a pipeline run ({shown or 'empty folders'}); elicit-jax "
            "writes only into a new folder or an earlier run's: choose another --out",
            run_dir,
        ) from e
    check_report_folder(run_dir / REPORT_DIR)


def run_pipeline(
    config: PipelineRunConfig,
    *,
    console: Any,
    registry: Mapping[str, StageFn] | None = None,
) -> PipelineOutcome:
    """Plan, run (skipping up-to-date stages), report and print the summary tables.

    Args:
      config: what to run.
      console: the ``rich`` console to show it on (the CLI's).
      registry: stage functions (default: every registered kind's,
        :func:`elicit_jax.pipeline.study_kinds.stage_functions`).
    """
    spec, graph, default_registry = plan_run(config)
    run_dir = Path(config.out) if config.out else default_run_dir(spec, config.tasks)
    note = " — CPU profile: shrunk networks/epochs, not the paper's sizes" * (spec.profile == "cpu")
    console.print(
        f"[bold]{spec.name}[/] ({spec.profile} profile{note}): {len(graph)} stages, "
        f"{len(spec.tasks)} task(s) × {len(spec.models)} model(s) × {len(spec.seeds)} seed(s)"
        f"{_collections_note(spec)} → {run_dir}"
    )
    check_run_dir(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    if config.ray is not None:
        from elicit_jax.pipeline.ray_runner import import_ray, run_graph_ray

        import_ray()
        execute = functools.partial(run_graph_ray, address=config.ray)
    else:
        execute = run_graph
    with run_lock(run_dir):
        write_manifest(run_dir, spec, graph)
        result = execute(
            graph,
            run_dir,
            registry or default_registry(),
            console=console,
            show_progress=config.progress,
            lock=False,
        )
    print_summary(result, console)
    print_results(run_dir, console)
    report = run_dir / REPORT_DIR
    console.print(f"report: {report / 'report.html'} (Markdown: {report / 'report.md'})")
    return PipelineOutcome(run_dir, result, report / "report.md", report / "report.html")


def pipeline_status(config: PipelineRunConfig, console: Any) -> dict[str, list[str]]:
    """Which stages of a run are up to date and which the next run would run (a stage whose
    upstream will run counts as to run); prints a table per kind.

    Returns:
      ``{"up to date": [ids], "to run": [ids]}``.
    """
    from rich.table import Table

    from elicit_jax.pipeline.runner import stage_up_to_date

    spec, graph, _ = plan_run(config)
    run_dir = Path(config.out) if config.out else default_run_dir(spec, config.tasks)
    out: dict[str, list[str]] = {"up to date": [], "to run": []}
    per_kind: dict[str, list[int]] = {}
    todo: set[str] = set()
    for stage in graph:
        upstream_todo = bool(todo & set(stage.inputs.values()))
        done = not upstream_todo and run_dir.exists() and stage_up_to_date(run_dir, graph, stage)
        if not done:
            todo.add(stage.id)
        out["up to date" if done else "to run"].append(stage.id)
        per_kind.setdefault(stage.kind, [0, 0])[0 if done else 1] += 1
    table = Table(title=f"{spec.name} ({spec.profile} profile) in {run_dir}")
    for col in ("stage", "up to date", "to run"):
        table.add_column(col, justify="left" if col == "stage" else "right")
    for kind, (done, todo) in per_kind.items():
        table.add_row(kind, str(done), str(todo))
    console.print(table)
    return out


def _collections_note(spec: Any) -> str:
    coll = getattr(spec, "collections", None)
    note = "" if coll is None else f" × {len(coll.seeds)} collections {list(coll.seeds)}"
    sizes = getattr(spec, "sizes", ("default",))
    return note + (f" × sizes {', '.join(sizes)}" if sizes != ("default",) else "")


def print_results(run_dir: Path, console: Any) -> None:
    """Print the run's result tables from its finished artifacts, as its study kind lays them
    out (a filtering study: the paper's layout, each table followed by its differences from
    Naive with their paired 95% intervals; an elicitation study: Table 2 and its ablations),
    then the run's notes."""
    from rich.table import Table

    kind = _kind_of_run(run_dir)
    data = kind.report_data(run_dir)
    for title, (header, rows) in kind.summary(data):
        table = Table(title=title)
        for col in header:
            table.add_column(col)
        for row in rows:
            table.add_row(*row)
        console.print(table)
    for note in data.notes:
        console.print(f"[yellow]{note}[/]")


def _kind_of_run(run_dir: Path) -> Any:
    """The study kind of a run directory (recorded in its manifest)."""
    from elicit_jax.pipeline.study_kinds import kind_of_run

    return kind_of_run(run_dir)


def render_run_report(
    run_dir: str | Path, out: str | Path | None = None, findings: str | Path | None = None
) -> tuple[Path, Path]:
    """(Re)write the report of a run directory, as its study kind writes it (a filtering
    pipeline, an elicitation study); returns the Markdown and HTML paths.

    Args:
      run_dir: the run directory.
      out: the report directory (default ``run_dir/report``).
      findings: a Markdown file of the authors' reading of the run, put first in the report
        and copied beside it (:mod:`elicit_jax.pipeline.findings`); it may live in ``out``.
    """
    from elicit_jax.pipeline.findings import read_findings

    run_dir = Path(run_dir)
    target = Path(out) if out else run_dir / REPORT_DIR
    notes = None if findings is None else read_findings(findings)
    kind = _kind_of_run(run_dir)
    data = kind.round_trip(dataclasses.replace(kind.report_data(run_dir), findings=notes))
    return kind.write_report(data, target)


def rebuild_report(folder: str | Path, out: str | Path | None = None) -> tuple[Path, Path]:
    """Rebuild a report from its folder alone: every table, interval and figure recomputed
    from the raw results kept beside it (``rollouts.parquet``, ``report-data.json``, its maps
    and ``findings.md``), without the run directory; returns the Markdown and HTML paths.

    Args:
      folder: a report folder written by this version of elicit-jax.
      out: where to write the rebuilt report (default: ``folder`` itself, replaced
        atomically).
    """
    from elicit_jax.pipeline.evidence import read_raw
    from elicit_jax.pipeline.findings import FINDINGS_FILE, read_findings
    from elicit_jax.pipeline.study_kinds import data_kinds, kind_of_data

    folder = Path(folder)
    header, rollouts = read_raw(folder, data_kinds())
    findings = None
    if (folder / FINDINGS_FILE).is_file():
        findings = read_findings(folder / FINDINGS_FILE)
    kind = kind_of_data(header["kind"])
    data = dataclasses.replace(kind.from_raw(header, rollouts, folder), findings=findings)
    return kind.write_report(data, Path(out) if out else folder, rebuilt_from=folder)
