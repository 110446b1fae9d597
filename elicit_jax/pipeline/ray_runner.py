"""Run a stage graph on a Ray cluster: each stage a Ray task, dispatched once its inputs exist.

The driver (this process) plans and decides; the workers do the work. A stage becomes ready
when every stage it reads from has finished (ran or was up to date). The driver then checks it
exactly as :func:`elicit_jax.pipeline.runner.run_graph` does (its record, config, input and
output hashes) and either skips it or submits it as a Ray task. The task sets up the JAX
runtime (:func:`elicit_jax.runtime.configure`) before it unpickles the stage function (and so
before anything imports JAX), runs it with :func:`elicit_jax.pipeline.runner.run_stage` and
writes the stage's completion record. Artifacts and records go straight into the run
directory, which must therefore be the same path on the driver and on every worker (a shared
file system such as NFS). Independent stages (the cells of the tasks × operators × seeds ×
models grid) run in parallel, as many at a time as the cluster has CPUs.

A failing task stops further dispatch; tasks already running finish and are recorded; then a
one-line :class:`~elicit_jax.errors.ElicitError` names the stage. Ctrl-C cancels the running
tasks (their outputs are written atomically, so nothing half-written remains) and the next run
resumes, like the local runner.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import elicit_jax
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.graph import Graph, Stage
from elicit_jax.pipeline.runner import (
    RunResult,
    StageFn,
    StageResult,
    clean_temporaries,
    run_lock,
    run_stage,
    stage_progress,
    stage_up_to_date,
)
from elicit_jax.provenance import COMMAND_ENV, current_command

RAY_HINT = "pip install 'elicit-jax[ray]'"


def import_ray() -> Any:
    """Import Ray, or fail with one line saying how to install the optional extra."""
    try:
        import ray
    except ImportError:
        raise ElicitError(f"--ray needs the optional Ray extra: {RAY_HINT}") from None
    return ray


@contextlib.contextmanager
def ray_session(address: str) -> Iterator[Any]:
    """Connect to Ray (or reuse the current connection) for the duration of a run.

    Args:
      address: ``local`` (start a private Ray instance on this machine, shut down afterwards),
        ``auto`` (the cluster started with ``ray start`` on this machine), ``HOST:PORT`` (a
        cluster's GCS address, driver on a cluster node) or ``ray://HOST:PORT`` (Ray Client).
        A local instance's workers import the driver's elicit_jax
        (:func:`driver_pythonpath`).
        If this process is already connected (``ray.init`` was called), that connection is
        used whatever the address.
    """
    ray = import_ray()
    if ray.is_initialized():
        yield ray
        return
    kwargs: dict[str, Any] = {"address": address, "log_to_driver": True}
    if address == "local":
        kwargs["include_dashboard"] = False
        kwargs["runtime_env"] = {"env_vars": {"PYTHONPATH": driver_pythonpath()}}
    try:
        ray.init(**kwargs)
    except (ConnectionError, RuntimeError, ValueError) as e:
        raise ElicitError(f"could not connect to Ray at '{address}': {_one_line(e)}") from None
    try:
        yield ray
    finally:
        ray.shutdown()


def driver_pythonpath() -> str:
    """``PYTHONPATH`` for a local cluster's workers: the driver's own elicit_jax comes first.

    A driver that found elicit_jax through ``sys.path`` (``python -m`` from a checkout, a
    notebook's ``sys.path.insert``) would otherwise have workers that import whichever
    elicit_jax is installed, and record that code's commit for the stages they run.
    """
    root = str(Path(elicit_jax.__file__).absolute().parent.parent)
    inherited = os.environ.get("PYTHONPATH", "")
    return os.pathsep.join(p for p in (root, inherited) if p)


def task_cpus() -> int | None:
    """CPUs Ray gave the running task (whole CPUs, at least 1), or None outside a task.

    Two one-CPU tasks on a 2-CPU machine each size XLA's thread pool to one thread rather than
    two: measured 2026-12-05, two concurrent cpu-profile trainings (5 seeds, 90 epochs) took
    97 s with one thread each and 108 s with two.
    """
    import ray

    try:
        cpus = ray.get_runtime_context().get_assigned_resources().get("CPU")
    except (AttributeError, RuntimeError):
        return None
    return None if cpus is None else max(1, int(cpus))


def stage_payload(stage: Stage) -> dict[str, Any]:
    """A picklable description of ``stage`` (its frozen mappings as plain dicts)."""
    return {
        "id": stage.id,
        "kind": stage.kind,
        "output": stage.output,
        "config": dict(stage.config),
        "inputs": dict(stage.inputs),
        "seed": stage.seed,
        "label": stage.label,
    }


def execute_remote(
    run_dir: str,
    payload: dict[str, Any],
    upstream: list[dict[str, Any]],
    fn_bytes: bytes,
    command: str,
) -> tuple[float, str]:
    """Body of a stage's Ray task: set up JAX, rebuild the stage, run it, record it.

    Args:
      run_dir: the shared run directory.
      payload: :func:`stage_payload` of the stage.
      upstream: payloads of the stages it reads from (only their ids and outputs are used).
      fn_bytes: the stage function, pickled on the driver and unpickled here after
        :func:`elicit_jax.runtime.configure`.
      command: the driver's command line, recorded in the provenance of what the stage
        writes (instead of the worker process's own).

    Returns:
      seconds the stage took, and what it printed on its console (without progress bars,
      which only the driver draws).
    """
    from elicit_jax.runtime import configure

    configure(cpus=task_cpus())
    os.environ[COMMAND_ENV] = command
    import io

    from ray import cloudpickle
    from rich.console import Console

    fn = cloudpickle.loads(fn_bytes)
    stage = Stage(**payload)
    deps = [Stage(id=u["id"], kind=u["kind"], output=u["output"]) for u in upstream]
    graph = Graph([*deps, stage])
    buffer = io.StringIO()
    console = Console(file=buffer, width=100, force_terminal=False)
    seconds = run_stage(Path(run_dir), graph, stage, fn, console)
    return seconds, "\n".join(line for line in buffer.getvalue().splitlines() if line.strip())


@dataclasses.dataclass
class _Dispatch:
    """Driver-side bookkeeping of one run: what finished, what is running, what failed."""

    graph: Graph
    results: dict[str, StageResult]
    running: dict[Any, Stage] = dataclasses.field(default_factory=dict)
    failure: tuple[Stage, BaseException] | None = None

    def finished(self, stage_id: str) -> bool:
        return self.results[stage_id].status in ("ran", "skipped")

    def ready(self) -> list[Stage]:
        busy = {s.id for s in self.running.values()}
        return [
            s
            for s in self.graph
            if self.results[s.id].status == "pending"
            and s.id not in busy
            and all(self.finished(dep) for dep in s.inputs.values())
        ]

    def done_count(self) -> int:
        return sum(self.finished(s.id) for s in self.graph)


def run_graph_ray(
    graph: Graph,
    run_dir: str | Path,
    registry: Mapping[str, StageFn],
    *,
    address: str = "local",
    console: Any,
    show_progress: bool = True,
    lock: bool = True,
) -> RunResult:
    """Run every stage of ``graph`` that is not up to date as Ray tasks (see module docs).

    Args:
      graph: the stages.
      run_dir: the run directory, on a file system every Ray worker sees at the same path.
      registry: stage kind -> function; must be picklable (module-level functions of a module
        the workers can import, e.g. :mod:`elicit_jax.pipeline.stages`).
      address: where Ray runs (see :func:`ray_session`).
      console: a ``rich`` console for the driver's progress and messages.
      show_progress: draw the overall progress bar.
      lock: take the run directory's lock (pass False when the caller already holds it).

    Returns:
      which stages ran and which were skipped, with the workers' timings.

    Raises:
      ElicitError: Ray is missing or unreachable, a kind is unregistered, or a stage failed
        (the message names it).
    """
    run_dir = Path(run_dir).resolve()
    missing = sorted({s.kind for s in graph} - set(registry))
    if missing:
        raise ElicitError(f"no stage function registered for kind(s): {', '.join(missing)}")
    run_dir.mkdir(parents=True, exist_ok=True)
    state = _Dispatch(graph, {s.id: StageResult(s, "pending") for s in graph})
    with (
        run_lock(run_dir) if lock else contextlib.nullcontext(),
        ray_session(address) as ray,
        stage_progress("pipeline (ray)", console, show_progress) as progress,
    ):
        clean_temporaries(run_dir)
        bar = progress.add_task("", total=len(graph))
        remote = ray.remote(max_retries=0)(execute_remote)
        pickled = {kind: ray.put(ray.cloudpickle.dumps(fn)) for kind, fn in registry.items()}
        try:
            _drive(ray, remote, pickled, run_dir, state, progress, bar)
        except KeyboardInterrupt:
            for ref in state.running:
                ray.cancel(ref, force=True)
            raise
        progress.update(bar, description="failed" if state.failure else "done")
    if state.failure is not None:
        stage, error = state.failure
        console.print(
            f"[red]stage failed:[/] {stage.id} ({state.done_count()} of {len(graph)} stages done "
            "and kept; re-run the same command to resume from here)"
        )
        raise ElicitError(f"stage '{stage.id}' failed on a Ray worker: {_one_line(error)}")
    return RunResult(run_dir, tuple(state.results[s.id] for s in graph))


def _drive(
    ray: Any,
    remote: Any,
    pickled: Mapping[str, Any],
    run_dir: Path,
    state: _Dispatch,
    progress: Any,
    bar: Any,
) -> None:
    """Skip or submit ready stages, collect finished tasks; stop dispatching after a failure."""
    graph = state.graph
    while True:
        if state.failure is None:
            skipped_some = True
            while skipped_some:
                skipped_some = False
                for stage in state.ready():
                    if stage_up_to_date(run_dir, graph, stage):
                        state.results[stage.id] = StageResult(stage, "skipped")
                        progress.advance(bar)
                        skipped_some = True
                        continue
                    upstream = [stage_payload(graph[d]) for d in stage.inputs.values()]
                    ref = remote.remote(
                        str(run_dir),
                        stage_payload(stage),
                        upstream,
                        pickled[stage.kind],
                        current_command(),
                    )
                    state.running[ref] = stage
        if not state.running:
            return
        labels = [s.label for s in state.running.values()]
        more = f" (+{len(labels) - 1} more)" if len(labels) > 1 else ""
        progress.update(bar, description=f"running: {labels[0]}{more}")
        (ref,), _ = ray.wait(list(state.running), num_returns=1)
        stage = state.running.pop(ref)
        try:
            outcome = ray.get(ref)
        except Exception as e:  # a RayTaskError wrapping the stage's own exception
            state.results[stage.id] = StageResult(stage, "failed")
            if state.failure is None:
                state.failure = (stage, getattr(e, "cause", None) or e)
            continue
        seconds, messages = outcome
        if messages:
            progress.console.print(messages, markup=False, highlight=False)
        state.results[stage.id] = StageResult(stage, "ran", float(seconds))
        progress.advance(bar)


def _one_line(error: BaseException) -> str:
    text = " ".join(str(error).split()) or "(no message)"
    if isinstance(error, ElicitError):
        return text
    return f"{type(error).__name__}: {text}"
