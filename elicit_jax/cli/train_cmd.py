"""``elicit-jax train``: behaviour-clone a base policy (MLP / MDN / LSTM ensemble)."""

from __future__ import annotations

from pathlib import Path

import typer

from elicit_jax.cli.app import POLICY, app
from elicit_jax.cli.params import field_params


def _int_list(text: str | None, flag: str) -> tuple[int, ...] | None:
    from elicit_jax.errors import ElicitError

    if text is None:
        return None
    try:
        values = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError as e:
        raise ElicitError(f"{flag} expects comma-separated integers, got {text!r}") from e
    if flag == "--seeds" and any(v < 0 for v in values):
        raise ElicitError(f"--seeds must be integers >= 0, got {text!r}")
    return values


@app.command(rich_help_panel=POLICY)
def train(
    ctx: typer.Context,
    demos: Path = typer.Option(..., "--demos", help="Training demonstrations (Parquet)."),
    out: Path = typer.Option(..., "--out", help="Run directory to write (one seed<k>/ per seed)."),
    model: str = typer.Option("mlp", "--model", help="mlp (ensemble), mdn or lstm."),
    profile: str | None = typer.Option(
        None,
        "--profile",
        help="paper (the paper's 5 x 2 x 1024, 1000 epochs), cpu (2 x 256, 100 epochs, 1 seed) "
        "or original-code (paper sizes, trained as the original code). Default: paper with a "
        "GPU/TPU, cpu on a CPU-only machine (printed).",
    ),
    epochs: int | None = typer.Option(None, "--epochs", help="Epochs (profile default)."),
    hidden: str | None = typer.Option(None, "--hidden", help="Hidden sizes, e.g. 1024,1024."),
    seeds: str | None = typer.Option(None, "--seeds", help="Training seeds, e.g. 0,1,2."),
    ensemble_size: int | None = typer.Option(None, "--ensemble-size", help="Members K."),
    lr: float | None = typer.Option(None, "--lr", help="Adam learning rate."),
    batch_size: int | None = typer.Option(None, "--batch-size", help="Minibatch size."),
    checkpoint_every: int | None = typer.Option(
        None, "--checkpoint-every", help="Save parameters every N epochs."
    ),
    val_fraction: float | None = typer.Option(
        None, "--val-fraction", help="Fraction of episodes held out for validation."
    ),
    dropout: float | None = typer.Option(None, "--dropout", help="Dropout between layers."),
    seq_len: int | None = typer.Option(None, "--seq-len", help="LSTM training window length."),
    bootstrap: bool | None = typer.Option(
        None, "--bootstrap/--no-bootstrap", help="Per-member bootstrap resampling."
    ),
    grad_clip: float | None = typer.Option(
        None, "--grad-clip", help="Clip gradients by global norm (original code: 10)."
    ),
    sequential_seeds: bool = typer.Option(
        False, "--sequential-seeds", help="Train seeds one after another (less memory)."
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar or summary."),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace an existing run of another config or other data."
    ),
) -> None:
    """Train a base policy on demonstrations and write a checkpoint directory.

    Without --profile the paper's sizes are used on an accelerator and the small cpu profile
    on a CPU-only machine (the paper's sizes take about 20 minutes per model on 2 CPU cores).

    Example: elicit-jax train --demos base.parquet --out runs/base --profile cpu --seeds 0,1,2
    """
    from elicit_jax.data.demos import read_demos
    from elicit_jax.policy.config import TrainConfig, default_profile
    from elicit_jax.policy.train import train_policy

    if profile is None:
        profile, why = default_profile()
        other = "cpu" if profile == "paper" else "paper"
        typer.echo(f"profile: {profile} ({why}; --profile {other} for the other)", err=True)

    config = TrainConfig.from_profile(
        profile,
        **field_params(TrainConfig, ctx.params)
        | {
            "hidden": _int_list(hidden, "--hidden"),
            "seeds": _int_list(seeds, "--seeds"),
            "vmap_seeds": False if sequential_seeds else None,
        },
    )
    train_policy(
        read_demos(demos), config, out, inputs={"demos": demos}, quiet=quiet, overwrite=overwrite
    )
    if not quiet:
        typer.echo(f"wrote {out}")
