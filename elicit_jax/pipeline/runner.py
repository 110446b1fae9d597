"""Run a stage graph: skip what is up to date, run the rest in order, resume after a kill.

After a stage's function returns, the runner writes a completion record
``RUN_DIR/.pipeline/stages/<id>.json``: an artifact header (kind ``pipeline-stage``) holding
the stage's config, the content hashes of its inputs and the hash of the output it wrote. A
stage is up to date when its record matches the current config and input hashes
(:func:`elicit_jax.artifact.is_up_to_date`) and its output still has the recorded hash. So a
second run does nothing; deleting or changing an artifact re-runs its stage and everything
downstream whose inputs then hash differently (artifact headers carry a creation time, so in
practice every dependent); a changed config re-runs only the stages
whose config changed and their dependents; a run killed mid-stage left no record for that
stage (outputs are written atomically), so the next run resumes there.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, Literal

from elicit_jax.artifact import (
    file_sha256,
    is_up_to_date,
    make_header,
    read_json,
    write_json,
)
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.graph import Graph, Stage
from elicit_jax.runtime import process_alive

STAGE_RECORD_KIND = "pipeline-stage"
STAGE_RECORD_SCHEMA = 1
STATE_DIR = ".pipeline"
Status = Literal["ran", "skipped", "failed", "pending"]


@dataclasses.dataclass(frozen=True)
class StageContext:
    """What a stage function gets: where to write, what to read, its config and seed.

    Attributes:
      stage: the stage being run.
      run_dir: the run directory.
      output: absolute path the function must write (atomically) before returning.
      inputs: input name -> absolute path of the upstream artifact.
      console: a ``rich`` console for messages and nested progress bars.
    """

    stage: Stage
    run_dir: Path
    output: Path
    inputs: Mapping[str, Path]
    console: Any

    @property
    def config(self) -> Mapping[str, Any]:
        return self.stage.config

    @property
    def seed(self) -> int | None:
        return self.stage.seed


StageFn = Callable[[StageContext], None]


@dataclasses.dataclass(frozen=True)
class StageResult:
    """Outcome of one stage in a run."""

    stage: Stage
    status: Status
    seconds: float = 0.0


@dataclasses.dataclass(frozen=True)
class RunResult:
    """Outcome of a whole run, in stage order."""

    run_dir: Path
    results: tuple[StageResult, ...]

    def ids(self, status: Status) -> list[str]:
        """Ids of the stages that ended with ``status``."""
        return [r.stage.id for r in self.results if r.status == status]

    @property
    def ran(self) -> list[str]:
        return self.ids("ran")

    @property
    def skipped(self) -> list[str]:
        return self.ids("skipped")


def record_path(run_dir: Path, stage: Stage) -> Path:
    """Where the completion record of ``stage`` lives."""
    return Path(run_dir) / STATE_DIR / "stages" / stage.record_name


def input_paths(run_dir: Path, graph: Graph, stage: Stage) -> dict[str, Path]:
    """Input name -> absolute path of the upstream stage's output."""
    return {name: Path(run_dir) / graph[dep].output for name, dep in stage.inputs.items()}


def stage_up_to_date(run_dir: Path, graph: Graph, stage: Stage) -> bool:
    """True when ``stage``'s record matches its config and inputs and its output is intact."""
    run_dir = Path(run_dir)
    rec = record_path(run_dir, stage)
    inputs = input_paths(run_dir, graph, stage)
    output = run_dir / stage.output
    if not output.exists() or any(not p.exists() for p in inputs.values()):
        return False
    if not is_up_to_date(rec, stage.config, inputs):
        return False
    return read_json(rec).get("output_sha256") == file_sha256(output)


def _write_record(run_dir: Path, graph: Graph, stage: Stage, seconds: float) -> None:
    output = run_dir / stage.output
    header = make_header(
        STAGE_RECORD_KIND,
        STAGE_RECORD_SCHEMA,
        config=dict(stage.config),
        inputs=input_paths(run_dir, graph, stage),
        seed=stage.seed,
        stage_id=stage.id,
        stage_kind=stage.kind,
        output=stage.output,
        output_sha256=file_sha256(output),
        seconds=round(seconds, 3),
    )
    write_json(record_path(run_dir, stage), header)


@contextlib.contextmanager
def run_lock(run_dir: Path) -> Iterator[None]:
    """Hold ``RUN_DIR/.pipeline/lock`` so two runners never write the same run at once.

    A lock left by a process that no longer exists (a killed run) is taken over.
    """
    lock = Path(run_dir) / STATE_DIR / "lock"
    lock.parent.mkdir(parents=True, exist_ok=True)
    for _ in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            pid = _lock_pid(lock)
            if pid is not None and pid != os.getpid() and process_alive(pid):
                raise ElicitError(
                    f"another pipeline run (pid {pid}) is using this run directory", run_dir
                ) from None
            lock.unlink(missing_ok=True)
            continue
        with os.fdopen(fd, "w") as f:
            f.write(str(os.getpid()))
        break
    else:
        raise ElicitError("could not take the run directory's lock", lock)
    try:
        yield
    finally:
        lock.unlink(missing_ok=True)


def _lock_pid(lock: Path) -> int | None:
    try:
        return int(lock.read_text().strip())
    except (OSError, ValueError):
        return None


def clean_temporaries(run_dir: Path) -> int:
    """Remove temporaries left by writes a killed run interrupted; returns how many.

    :func:`elicit_jax.artifact.atomic_path` writes into ``.<name>.<random>.tmp`` directories
    beside the target; only call this while holding the run lock.
    """
    import shutil

    stale = [p for p in Path(run_dir).rglob(".*.tmp") if p.is_dir()]
    for p in stale:
        shutil.rmtree(p, ignore_errors=True)
    return len(stale)


def run_stage(run_dir: Path, graph: Graph, stage: Stage, fn: StageFn, console: Any) -> float:
    """Run one stage's function, check it wrote its output, record it; returns seconds."""
    t0 = time.perf_counter()
    ctx = StageContext(
        stage=stage,
        run_dir=run_dir,
        output=run_dir / stage.output,
        inputs=input_paths(run_dir, graph, stage),
        console=console,
    )
    ctx.output.parent.mkdir(parents=True, exist_ok=True)
    fn(ctx)
    if not ctx.output.exists():
        raise ElicitError(f"stage '{stage.id}' finished without writing its output")
    seconds = time.perf_counter() - t0
    _write_record(run_dir, graph, stage, seconds)
    return seconds


def stage_progress(label: str, console: Any, show: bool) -> Any:
    """The overall progress bar of a run (stages done of all, time, the stage running)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(
        TextColumn(f"[bold]{label}[/]"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("{task.description}"),
        console=console,
        disable=not show,
        transient=False,
    )


def run_graph(
    graph: Graph,
    run_dir: str | Path,
    registry: Mapping[str, StageFn],
    *,
    console: Any,
    show_progress: bool = True,
    lock: bool = True,
) -> RunResult:
    """Run every stage of ``graph`` that is not up to date, in topological order.

    Shows an overall bar (stages done / total, current stage); stage functions draw their own
    nested bars on ``ctx.console``. Stops at the first failing stage (the error propagates);
    everything finished before it stays recorded, so the next run resumes from there.

    Args:
      graph: the stages.
      run_dir: the run directory (created if missing).
      registry: stage kind -> function doing the work.
      console: the ``rich.console.Console`` to show the run on (the caller's).
      show_progress: draw the overall progress bar.
      lock: take the run directory's lock (pass False when the caller already holds it).

    Returns:
      which stages ran and which were skipped, with timings.
    """
    run_dir = Path(run_dir)
    missing = sorted({s.kind for s in graph} - set(registry))
    if missing:
        raise ElicitError(f"no stage function registered for kind(s): {', '.join(missing)}")
    results: dict[str, StageResult] = {s.id: StageResult(s, "pending") for s in graph}
    progress = stage_progress("pipeline", console, show_progress)
    with run_lock(run_dir) if lock else contextlib.nullcontext(), progress:
        clean_temporaries(run_dir)
        bar = progress.add_task("", total=len(graph))
        for stage in graph:
            progress.update(bar, description=stage.label)
            if stage_up_to_date(run_dir, graph, stage):
                results[stage.id] = StageResult(stage, "skipped")
                progress.advance(bar)
                continue
            try:
                seconds = run_stage(run_dir, graph, stage, registry[stage.kind], console)
            except BaseException:
                results[stage.id] = StageResult(stage, "failed")
                done = sum(r.status in ("ran", "skipped") for r in results.values())
                console.print(
                    f"[red]stage failed:[/] {stage.id} ({done} of {len(graph)} stages done and "
                    "kept; re-run the same command to resume from here)"
                )
                raise
            results[stage.id] = StageResult(stage, "ran", seconds)
            progress.advance(bar)
        progress.update(bar, description="done")
    return RunResult(run_dir, tuple(results[s.id] for s in graph))


def summary_rows(result: RunResult) -> list[tuple[str, int, int, int, float]]:
    """Per stage kind: (kind, total, ran, skipped, seconds spent running)."""
    rows: dict[str, list[float]] = {}
    for r in result.results:
        row = rows.setdefault(r.stage.kind, [0, 0, 0, 0.0])
        row[0] += 1
        row[1] += r.status == "ran"
        row[2] += r.status == "skipped"
        row[3] += r.seconds
    return [(k, int(a), int(b), int(c), float(d)) for k, (a, b, c, d) in rows.items()]


def print_summary(result: RunResult, console: Any) -> None:
    """Print the per-kind table of what ran and what was skipped."""
    from rich.table import Table

    table = Table(title=f"pipeline stages ({result.run_dir})")
    for col in ("stage", "total", "ran", "skipped (up to date)", "time"):
        table.add_column(col, justify="left" if col == "stage" else "right")
    for kind, total, ran, skipped, seconds in summary_rows(result):
        table.add_row(kind, str(total), str(ran), str(skipped), f"{seconds:.1f}s")
    console.print(table)
