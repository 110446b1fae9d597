"""Simulation commands: tasks, collect, evaluate."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from elicit_jax.cli.app import DATA, HAND_BACK, INSPECT, app, check_seed, log_path
from elicit_jax.cli.outputs import OVERWRITE, policy_dirs
from elicit_jax.cli.params import from_params
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    import pandas as pd

    from elicit_jax.sim.evaluate import EvalConfig
    from elicit_jax.sim.trajectories import TrajectoryConfig


@app.command(rich_help_panel=INSPECT)
def tasks() -> None:
    """List the simulated tasks, their horizons and scripted operators.

    Example: elicit-jax tasks
    """
    from rich.console import Console
    from rich.table import Table

    from elicit_jax.sim.env import make_task, task_names
    from elicit_jax.sim.operators import operator_names

    table = Table("task", "horizon", "operator", "style")
    for name in task_names():
        task = make_task(name)
        for i, (op, desc) in enumerate(operator_names(name).items()):
            table.add_row(
                name if i == 0 else "", str(task.config.horizon) if i == 0 else "", op, desc
            )
    Console().print(table)


@app.command(rich_help_panel=DATA)
def collect(
    ctx: typer.Context,
    task: str = typer.Option("square-nut", "--task", help="Task name (see `elicit-jax tasks`)."),
    operator: str = typer.Option("base", "--operator", help="Scripted operator name."),
    episodes: int = typer.Option(50, "--episodes", help="Successful demonstrations to keep."),
    seed: int = typer.Option(
        0, "--seed", help="Seed of initial states and operator noise.", callback=check_seed
    ),
    max_attempts: int = typer.Option(0, "--max-attempts", help="Give up after (0: 4 x episodes)."),
    threads: int = typer.Option(
        0, "--threads", help="C MuJoCo threads or robosuite processes (0: one per CPU)."
    ),
    require: str = typer.Option(
        "",
        "--require",
        help="Keep only demos whose measured traits say they conflict ('conflicts') or not "
        "('no-conflict'); robosuite nut tasks.",
    ),
    out: Path = typer.Option(..., "-o", "--out", help="Demos artifact to write (.parquet)."),
    overwrite: bool = OVERWRITE,
) -> None:
    """Collect scripted demonstrations (C MuJoCo, or robosuite for its tasks); only
    successful episodes are kept.

    Example: elicit-jax collect --task square-nut --operator base --episodes 50 --seed 0
    -o base.parquet
    """
    import time

    from rich.console import Console
    from rich.progress import Progress

    from elicit_jax.artifact import check_outputs
    from elicit_jax.sim.collect import CollectConfig
    from elicit_jax.sim.collect import collect as run

    check_outputs([out], overwrite=overwrite)
    config = from_params(CollectConfig, ctx.params)
    t0 = time.perf_counter()
    with Progress(transient=True) as bar:
        tid = bar.add_task(f"{task} / {operator}", total=episodes)
        result = run(config, out, progress=lambda kept, _att: bar.update(tid, completed=kept))
    Console().print(
        f"{out}: {len(result.episodes)} demos of '{operator}' on {task}; attempt success "
        f"{result.successes}/{result.attempts} ({100 * result.success_rate:.0f}%), mean length "
        f"{sum(result.lengths) / len(result.lengths):.0f} steps, {time.perf_counter() - t0:.1f} s"
    )
    if result.conflicting is not None:
        left_out = f"; {result.unverified} successful demos not '{require}' left out"
        Console().print(
            f"measured per demo: {result.conflicting} of {len(result.episodes)} conflict with "
            "the base operator's way (column 'conflicts'; docs/operators.md)"
            + (left_out if result.unverified else "")
        )


@app.command(rich_help_panel=HAND_BACK)
def evaluate(
    ctx: typer.Context,
    policy: list[str] = typer.Option(
        ..., "--policy", help="Run directory, or LABEL=DIR (same label = seeds); repeatable."
    ),
    task: str | None = typer.Option(
        None,
        "--task",
        help="Task name (default: the task the policies were trained on; another one is "
        "refused without --force).",
    ),
    force: bool = typer.Option(
        False, "--force", help="Evaluate on --task although the policies record another task."
    ),
    rollouts: int = typer.Option(50, "--rollouts", help="Rollouts per policy."),
    seed: int = typer.Option(
        0, "--seed", help="Seed of the set of initial states.", callback=check_seed
    ),
    backend: str = typer.Option(
        "auto", "--backend", help="auto, mjx, mujoco (C MuJoCo) or robosuite (its tasks)."
    ),
    checkpoint: list[str] = typer.Option(
        ["best"], "--checkpoint", help="best, final, all or an epoch; repeatable."
    ),
    select: str = typer.Option("all", "--select", help="all, or best checkpoint per seed."),
    horizon: int = typer.Option(0, "--horizon", help="Control steps (0: the task's)."),
    threads: int = typer.Option(0, "--threads", help="C MuJoCo threads (0: one per CPU)."),
    env_from: Path | None = typer.Option(
        None, "--env-from", help="robomimic .hdf5: evaluate in the robosuite env it names."
    ),
    workers: int = typer.Option(0, "--workers", help="robosuite processes (0: one per CPU)."),
    out: Path | None = typer.Option(None, "-o", "--out", help="Per-rollout Parquet to write."),
    trajectories: Path | None = typer.Option(
        None, "--trajectories", help="Also record every step (state, action) to this Parquet."
    ),
    action_noise: float = typer.Option(
        0.0, "--action-noise", help="With --trajectories: std of Gaussian exploration noise."
    ),
    overwrite: bool = OVERWRITE,
) -> None:
    """Evaluate policies with rollouts from the same seeded initial states.

    With --trajectories every state each policy acted in, the action it took and its
    rollout's outcome are recorded (C MuJoCo); --action-noise adds seeded Gaussian
    exploration noise to the actions (CUPID's rollouts need it: docs/curation.md).

    Example: elicit-jax evaluate --policy runs/base --task square-nut --rollouts 50
    --checkpoint all --select best -o evals.parquet

    Example: elicit-jax evaluate --policy runs/naive --task square-nut --rollouts 50
    --backend mujoco --trajectories steps.parquet --action-noise 0.1

    Example: elicit-jax evaluate --policy runs/base --env-from square_ph.hdf5 --rollouts 50
    """
    import time

    from rich.console import Console

    from elicit_jax.artifact import check_outputs
    from elicit_jax.sim.evaluate import EvalConfig

    check_outputs([out, trajectories], policy_dirs(policy), overwrite=overwrite)
    task, notes = _eval_task(task, policy, env_from, force)
    config = from_params(
        EvalConfig,
        ctx.params,
        task=task,
        checkpoints=tuple(checkpoint),
        env_from=str(env_from or ""),
    )
    traj = _trajectory_config(trajectories, action_noise)
    console = Console()
    for note in notes:
        console.print(note, soft_wrap=True)
    console.print(_backend_line(config))
    label = config.task if env_from is None else f"{env_from.name}'s env"
    t0 = time.perf_counter()
    n, summary = _evaluate_with_bar(policy, config, out, traj, label)
    print_summary(console, summary)
    console.print(f"{n} policies evaluated in {time.perf_counter() - t0:.1f} s")
    for note in _evaluation_notes(config, summary):
        console.print(note)


def _eval_task(
    task: str | None, policy: list[str], env_from: Path | None, force: bool
) -> tuple[str, list[str]]:
    """The task to evaluate on (the policies' recorded one by default; another only with
    ``--force``) and the notes to print; with ``--env-from`` the file names the
    environment and ``--task`` is not used."""
    from elicit_jax.sim.evaluate import EvalConfig
    from elicit_jax.sim.task_match import resolve_task

    if env_from is not None:
        return task or EvalConfig.task, []
    chosen, notes = resolve_task(task, policy_dirs(policy), force)
    if task is None:
        notes.insert(0, f"task: {chosen} (recorded by the policies' training run)")
    return chosen, notes


def _evaluate_with_bar(
    policy: list[str],
    config: EvalConfig,
    out: Path | None,
    traj: TrajectoryConfig | None,
    label: str,
) -> tuple[int, pd.DataFrame]:
    """Run the evaluation under a progress bar; the number of policies and the summary."""
    from rich.progress import Progress

    from elicit_jax.sim.evaluate import evaluate_policies, expand_policies, resolve_backend

    n = len(expand_policies(policy, config.checkpoints))
    what = f"{label}: {n} policies x {config.rollouts} rollouts"
    first = what
    if resolve_backend(config.backend, config.task, config.env_from) == "mjx":
        first = f"{what} — compiling… (MJX: minutes when not cached)"

    def done(_ref: object, _rate: object) -> None:
        bar.update(tid, advance=1, description=what)

    with Progress(transient=True) as bar:
        tid = bar.add_task(first, total=n)
        _, summary = evaluate_policies(policy, config, out, progress=done, trajectories=traj)
    return n, summary


def _trajectory_config(trajectories: Path | None, action_noise: float) -> TrajectoryConfig | None:
    """``--trajectories`` (with its ``--action-noise``) as a TrajectoryConfig, or None."""
    if trajectories is None:
        if action_noise:
            raise ElicitError("--action-noise only applies with --trajectories")
        return None
    from elicit_jax.sim.trajectories import TrajectoryConfig

    return TrajectoryConfig(out=str(trajectories), action_noise=action_noise)


def _backend_line(config: EvalConfig) -> str:
    """Which simulator the rollouts run on, and why when ``auto`` chose it."""
    from elicit_jax.sim.evaluate import resolve_backend

    chosen = resolve_backend(config.backend, config.task, config.env_from)
    auto = config.backend == "auto" and chosen == "mujoco"
    reason = " (auto: JAX runs on CPU)" if auto else ""
    names = {"mujoco": "C MuJoCo", "mjx": "MJX", "robosuite": "robosuite (worker processes)"}
    return f"backend: {names[chosen]}{reason}"


def _evaluation_notes(config: EvalConfig, summary: pd.DataFrame) -> list[str]:
    """What the user should know about the numbers above: a checkpoint chosen on the same
    rollouts (biased upwards), rollouts whose physics diverged."""
    notes = []
    checkpoints = config.checkpoints
    if config.select == "best" and (len(checkpoints) > 1 or "all" in checkpoints):
        notes.append(
            "note: --select best chose each seed's checkpoint on these same rollouts, so the "
            "success above is biased upwards; for an unbiased number evaluate the chosen "
            "checkpoints again with another --seed (the pipelines choose on held-out rollouts: "
            "docs/results.md)"
        )
    unstable = int(summary["unstable"].sum())
    if unstable:
        notes.append(
            f"{unstable} rollout(s) diverged (the physics became unstable) and count as "
            f"failures; MuJoCo's messages are in the log: {log_path()}"
        )
    return notes


def print_summary(console: object, summary: object) -> None:
    """Print an evaluation summary table."""
    from rich.table import Table

    table = Table(
        "policy", "checkpoint", "seeds", "success % mean (std)", "mean length", "unstable"
    )
    for row in summary.to_dict(orient="records"):  # type: ignore[attr-defined]
        table.add_row(
            str(row["policy"]),
            str(row["checkpoint"]),
            str(row["n_seeds"]),
            f"{row['success_mean']:.1f} "
            + ("(–)" if row["n_seeds"] < 2 else f"({row['success_std']:.1f})"),
            f"{row['mean_length']:.1f}",
            str(row.get("unstable", 0)),
        )
    console.print(table)  # type: ignore[attr-defined]
