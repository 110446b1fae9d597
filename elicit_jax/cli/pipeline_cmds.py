"""Pipeline commands: ``pipeline run``, ``report``, ``quickstart``."""

from __future__ import annotations

from pathlib import Path

import typer

from elicit_jax.cli.app import PIPELINES, app, command_group

pipeline_app = command_group(
    "pipeline",
    "Run a pipeline definition (collect → train → score → fit → filter → train → evaluate).",
    PIPELINES,
)

_PROFILE_HELP = "paper (the paper's sizes) or cpu (shrunk to fit a 2-core machine)."
_TASKS_HELP = "Comma-separated tasks of the definition to run [all]."
_SIZES_HELP = (
    "Named study sizes to run side by side, comma-separated: default (the tasks' own "
    "D_base/D_new counts) or a [task.sizes.NAME] of the definition, e.g. paper [the "
    "definition's [pipeline] sizes, else default]."
)


def _tasks(value: str | None) -> tuple[str, ...] | None:
    return tuple(t.strip() for t in value.split(",") if t.strip()) if value else None


@pipeline_app.command("run")
def pipeline_run(
    definition: str = typer.Argument(
        ...,
        help="A pipeline TOML file, or a shipped one: quickstart, filtering, models, elicitation, "
        "phenomenon, robosuite, phenomenon-robosuite.",
    ),
    profile: str = typer.Option(None, "--profile", help=_PROFILE_HELP),
    out: Path = typer.Option(None, "--out", "-o", help="Run directory [runs/<name>-<profile>]."),
    tasks: str = typer.Option(None, "--tasks", help=_TASKS_HELP),
    sizes: str = typer.Option(None, "--sizes", help=_SIZES_HELP),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Progress bars."),
    ray: str = typer.Option(
        None,
        "--ray",
        help="Run stages as Ray tasks: local, auto, HOST:PORT or ray://HOST:PORT "
        "(needs the 'ray' extra; --out must be on a file system every node shares).",
    ),
) -> None:
    """Run every stage that is not up to date; a re-run skips finished stages.

    Examples:
      elicit-jax pipeline run pipelines/filtering.toml --profile cpu --tasks square-nut
      elicit-jax pipeline run filtering --out runs/filtering --ray auto
      elicit-jax pipeline run robosuite --profile cpu --sizes default,paper
    """
    from rich.console import Console

    from elicit_jax.pipeline.run import PipelineRunConfig, run_pipeline

    config = PipelineRunConfig(
        pipeline=definition,
        profile=profile,
        out=None if out is None else str(out),
        progress=progress,
        ray=ray,
        tasks=_tasks(tasks),
        sizes=sizes,
    )
    run_pipeline(config, console=Console())


@pipeline_app.command("status")
def pipeline_status(
    definition: str = typer.Argument(..., help="A pipeline TOML file, or a shipped one."),
    profile: str = typer.Option(None, "--profile", help=_PROFILE_HELP),
    out: Path = typer.Option(None, "--out", "-o", help="Run directory [runs/<name>-<profile>]."),
    tasks: str = typer.Option(None, "--tasks", help=_TASKS_HELP),
    sizes: str = typer.Option(None, "--sizes", help=_SIZES_HELP),
) -> None:
    """Show which stages are up to date and which the next run would run (runs nothing).

    Example: elicit-jax pipeline status pipelines/filtering.toml --profile cpu
    """
    from rich.console import Console

    from elicit_jax.pipeline.run import PipelineRunConfig, pipeline_status

    pipeline_status(
        PipelineRunConfig(
            pipeline=definition,
            profile=profile,
            out=None if out is None else str(out),
            tasks=_tasks(tasks),
            sizes=sizes,
        ),
        Console(),
    )


@app.command("report", rich_help_panel=PIPELINES)
def report(
    run_dir: Path = typer.Argument(..., help="A pipeline run or an elicitation session."),
    out: Path = typer.Option(None, "--out", "-o", help="Report directory [RUN_DIR/report]."),
    findings: Path = typer.Option(
        None,
        "--findings",
        help="Markdown file of your reading of the run, put first in a pipeline or study "
        "report and copied beside it as findings.md (it may be the previous report's copy).",
    ),
    rebuild: bool = typer.Option(
        False,
        "--rebuild",
        help="RUN_DIR is a report folder: recompute every table, interval and figure from the "
        "raw results kept in it (rollouts.parquet, report-data.json), without the run.",
    ),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace an existing report (never another directory)."
    ),
) -> None:
    """Write the Markdown and self-contained HTML report of a pipeline run or a session.

    An existing report (a pipeline run writes RUN_DIR/report) is replaced only with
    --overwrite; any other directory never. --rebuild without -o rewrites the report folder
    it is given, which is what it is for.

    Examples:
      elicit-jax report sessions/op4
      elicit-jax report runs/filtering-cpu --overwrite
      elicit-jax report runs/filtering-cpu -o docs/results/f --findings docs/results/f/findings.md
      elicit-jax report --rebuild docs/results/f
    """
    from elicit_jax.artifact import check_outputs, holds_artifact, read_json
    from elicit_jax.pipeline.report_folder import check_report_folder

    # an existing report is replaced only with --overwrite, and never when it holds the user's
    # own files (a rebuild in place needs no check here: rebuild_report refuses a folder
    # without raw results)
    target = out or (None if rebuild else run_dir / "report")
    check_outputs(
        [target],
        overwrite=overwrite,
        replaceable=holds_artifact("pipeline-report", "study-report", "session-report"),
    )
    if target is not None:
        check_report_folder(target)
    if rebuild:
        from elicit_jax.pipeline.run import rebuild_report

        if findings is not None:
            from elicit_jax.errors import ElicitError

            raise ElicitError("--rebuild uses the findings.md kept in the folder", run_dir)
        md, page = rebuild_report(run_dir, out)
        typer.echo(f"rebuilt {md} and {page}")
        return

    header = read_json(run_dir / "artifact.json") if (run_dir / "artifact.json").is_file() else {}
    if isinstance(header, dict) and header.get("kind") == "elicit-session":
        from elicit_jax.elicit.report import write_session_report

        if findings is not None:
            from elicit_jax.errors import ElicitError

            raise ElicitError("--findings is for pipeline and study reports", run_dir)

        md, page = write_session_report(run_dir, out)
        typer.echo(f"wrote {md} and {page}")
        return
    from elicit_jax.pipeline.run import render_run_report

    md, page = render_run_report(run_dir, out, findings)
    typer.echo(f"wrote {md} and {page}")


@app.command("quickstart", rich_help_panel=PIPELINES)
def quickstart(
    out: Path = typer.Option(None, "--out", "-o", help="Run directory [runs/quickstart-cpu]."),
) -> None:
    """Run the shipped quickstart pipeline (a few minutes on a 2-core CPU) and print results.

    Example: elicit-jax quickstart
    """
    from rich.console import Console

    from elicit_jax.pipeline.run import PipelineRunConfig, run_pipeline

    config = PipelineRunConfig(pipeline="quickstart", out=None if out is None else str(out))
    run_pipeline(config, console=Console())
