"""The ``score`` command: per-pair compatibility scores of demonstrations under a base policy,
with the thresholds it falls back to when none are given (the demos' task's paper preset)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from elicit_jax.cli import threshold_options as th
from elicit_jax.cli.app import COMPAT, app, check_seed
from elicit_jax.cli.outputs import OVERWRITE
from elicit_jax.cli.params import from_params, with_flags
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.compat.thresholds import Thresholds


@app.command(rich_help_panel=COMPAT)
@with_flags((*th.FLAGS_AND_PRESET, ("force", bool, th.FORCE)), before="likelihood")
def score(
    ctx: typer.Context,
    policy: Path = typer.Option(..., "--policy", help="Base policy checkpoint or run directory."),
    demos: Path = typer.Option(..., "--demos", help="Demonstrations to score (demos artifact)."),
    out: Path = typer.Option(..., "-o", "--out", help="Scores artifact to write (.parquet)."),
    likelihood: str = typer.Option(
        "ensemble-mean", "--likelihood", help="ensemble-mean (paper) or member-average (code)."
    ),
    ddof: int = typer.Option(0, "--ddof", help="Std convention of novelty: 0 paper, 1 code."),
    action_scale: str = typer.Option(
        "none",
        "--action-scale",
        help="none (paper: raw action units) or std (each dim divided by the training actions' "
        "std; dims constant there by the others' median std).",
    ),
    dropout_samples: int = typer.Option(
        0,
        "--dropout-samples",
        help="MC-dropout scoring: N passes per member with dropout on (the original code "
        "scored with dropout on). 0 = deterministic members (paper).",
    ),
    dropout_seed: int = typer.Option(
        0, "--dropout-seed", help="Seed of the dropout masks.", callback=check_seed
    ),
    accept_fraction: float = typer.Option(
        0.05, "--accept-fraction", help="Reject a demo above this fraction incompatible."
    ),
    chunk_size: int = typer.Option(4096, "--chunk-size", help="Pairs per compiled chunk."),
    which: str = typer.Option("best", "--which", help="Checkpoint: best, final or an epoch."),
    seed: int | None = typer.Option(
        None, "--seed", help="Seed of a multi-seed run directory.", callback=check_seed
    ),
    overwrite: bool = OVERWRITE,
    **flags: Any,
) -> None:
    """Score every state-action pair: likelihood error, novelty, compatibility M.

    Writes per-pair scores to OUT and a per-episode summary (5% accept/reject rule) next to
    it as OUT.episodes.parquet, and prints a table per operator.

    Without thresholds, the paper's preset of the demos' task is used (NutAssemblyRound ->
    round-nut, ...); for other tasks square-nut's values stand in, with a warning: fit your own
    with fit-thresholds.

    Example: elicit-jax score --policy runs/base --demos new.parquet -o scores.parquet
    --preset round-nut
    """
    from elicit_jax.artifact import check_outputs
    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.compat.score import episodes_path

    chosen = _score_thresholds(demos, ctx.params, action_scale)
    inputs = [demos, policy, flags["thresholds"]]
    check_outputs([out, episodes_path(out)], inputs, overwrite=overwrite)
    config = from_params(ScoreConfig, ctx.params, thresholds=chosen)
    which_: str | int = int(which) if which.isdigit() else which
    _score_and_show(policy, demos, out, config, which_, seed, flags["force"])


def _score_and_show(
    policy: Path,
    demos: Path,
    out: Path,
    config: ScoreConfig,
    which: str | int,
    seed: int | None,
    force: bool,
) -> None:
    """Load the checkpoint, check a thresholds file was fitted for it, warn about a
    one-member policy, score with a progress bar and print a table per operator."""
    from rich.console import Console

    from elicit_jax.cli.info_compat import print_operator_table
    from elicit_jax.compat.score_file import one_member_note, scale_note, score_file
    from elicit_jax.compat.show import scoring_bar
    from elicit_jax.compat.threshold_source import check_policy
    from elicit_jax.policy.loaded import load_policy

    loaded = load_policy(policy, which, seed=seed)
    chosen = config.thresholds
    if chosen is None:
        raise ElicitError("score needs thresholds: none resolved")
    typer.echo(f"thresholds: {chosen.describe()}", err=True)
    warning = check_policy(chosen, loaded.sha256, str(policy), force)
    if warning:
        typer.echo(warning, err=True)
    scaled = scale_note(loaded.policy, config).get("action_scale_note")
    if scaled:
        typer.echo(f"note: --action-scale std: {scaled}", err=True)
    note = one_member_note(loaded.policy, config)
    if note:
        Console(stderr=True).print(f"[yellow]warning:[/] {note}", soft_wrap=True)
    result = score_file(
        loaded.policy,
        demos,
        out,
        config,
        policy_path=policy,
        policy_info={"which": which, "seed": seed},
        progress=scoring_bar,
    )
    print_operator_table(
        result.episodes,
        title=f"{demos.name} scored (λ={chosen.lam:.3g}, η={chosen.eta:.3g}, "
        f"reject > {100 * config.accept_fraction:g}% incompatible)",
    )


def _score_thresholds(demos: Path, params: Mapping[str, Any], action_scale: str) -> Thresholds:
    """``score``'s (λ, η) and where they came from, in the units of ``action_scale``: the
    flags', else the demos' task's (:func:`~elicit_jax.compat.threshold_source.task_thresholds`)."""
    from elicit_jax.artifact import read_header
    from elicit_jax.compat.threshold_source import task_thresholds

    given = th.from_params(params, action_scale)
    if given is None:
        chosen, notes = task_thresholds(read_header(demos).get("task", "unknown"), action_scale)
        for note in notes:
            typer.echo(note, err=True)
        return chosen
    if action_scale == "std" and params["thresholds"] is None:
        typer.echo("thresholds: --lambda/--eta read in std-scaled units", err=True)
        return dataclasses.replace(given, source=given.source + " (std-scaled units)")
    return given
