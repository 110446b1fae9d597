"""The ``filter`` command's flags, and the configs and output checks they turn into.

``filter`` takes the M-filter's flags, its baselines' and those of every curation method
(deminf, demo-score, cupid, quality); they are declared here so the command itself stays a
thin shell: parse, check the outputs, build one config, call one library function, print.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from elicit_jax.cli.app import check_seed
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.compat.filtering import ExportSpec, FilterConfig
    from elicit_jax.compat.thresholds import Thresholds

CURATORS = ("deminf", "demo-score", "cupid", "quality")
"""The ``--method`` values that are curation methods (docs/curation.md), not the M-filter."""

SCORES = typer.Option(
    None, "--scores", help="Scores of --demos (deminf/demo-score: only with --rate m)."
)
DEMOS = typer.Option(..., "--demos", help="New demonstrations D_new.")
OUT = typer.Option(..., "-o", "--out", help="Filtered demos artifact (.parquet).")
BASE = typer.Option(None, "--base", help="D_base, kept whole, placed first.")
LEVEL = typer.Option("pair", "--level", help="pair or episode.")
METHOD = typer.Option(
    "m",
    "--method",
    help="m | random | shortest | longest | likelihood | novelty | deminf | demo-score | "
    "cupid | quality.",
)
PAIR_MODE = typer.Option(
    "renumber", "--pair-mode", help="After dropping pairs: renumber steps or split episodes."
)
SEED = typer.Option(0, "--seed", help="Seed of the random baseline.", callback=check_seed)
EXPORT = typer.Option(
    None, "--export", help="Also export kept episodes: robomimic (mask) or lerobot."
)
EXPORT_OUT = typer.Option(
    None, "--export-out", help="robomimic: the .hdf5 copy; lerobot: folder or .json list."
)
MASK_KEY = typer.Option(None, "--mask-key", help="robomimic: new filter key.")
SOURCE = typer.Option(
    None, "--source", help="Original dataset for --export (default: recorded at import)."
)
RATE = typer.Option(
    "own", "--rate", help="deminf/demo-score: own (their own cut) or m (M-filter's amount)."
)
DROP_FRACTION = typer.Option(
    0.2, "--drop-fraction", help="deminf's own cut: lowest fraction of demos."
)
POLICY = typer.Option(
    None, "--policy", help="demo-score: training run to roll out (trained on the data)."
)
TASK = typer.Option(None, "--task", help="demo-score: task (default: the demos' task).")
ROLLOUTS = typer.Option(100, "--rollouts", help="demo-score: rollouts per checkpoint.")
POLICY_SEED = typer.Option(
    None, "--policy-seed", help="demo-score: training seed of --policy (default: its first)."
)
TRAJECTORIES = typer.Option(
    None, "--trajectories", help="cupid: evaluate --trajectories of --policy (noisy)."
)
CHECKPOINT = typer.Option(
    "best", "--checkpoint", help="cupid: the checkpoint of --policy that was rolled out."
)
PROJ_DIM = typer.Option(512, "--proj-dim", help="cupid: gradient projection dim.")


def check_filter_outputs(
    out: Path, method: str, export_out: Path | None, overwrite: bool, inputs: list
) -> None:
    """Every file ``filter`` writes (the demos, its drop log or per-demo scores, an export),
    checked by the one output rule before any work."""
    from elicit_jax.artifact import check_outputs
    from elicit_jax.compat.filtering import log_path
    from elicit_jax.curation.select import scores_path_for
    from elicit_jax.data.export_config import is_lerobot_dataset

    outs = [out, log_path(out)] + ([scores_path_for(out)] if method in CURATORS else [])
    check_outputs(outs, inputs, overwrite=overwrite)
    check_outputs([export_out], inputs, overwrite=overwrite, replaceable=is_lerobot_dataset)


def filter_config(
    scores: Path | None,
    level: str,
    method: str,
    pair_mode: str,
    thresholds: Thresholds | None,
    seed: int,
) -> FilterConfig:
    """The M-filter's (or a baseline's) config; they need the scores of ``--demos``."""
    from elicit_jax.compat.filtering import FilterConfig

    if scores is None:
        raise ElicitError(f"--method {method} filters by compatibility scores: give --scores")
    return FilterConfig(
        level=level,  # type: ignore[arg-type]
        method=method,
        pair_mode=pair_mode,  # type: ignore[arg-type]
        thresholds=thresholds,
        seed=seed,
    )


def export_spec(
    export: str | None,
    export_out: Path | None,
    mask_key: str | None,
    source: Path | None,
    overwrite: bool,
) -> ExportSpec | None:
    """What ``--export`` asks for (None without it)."""
    from elicit_jax.compat.filtering import ExportSpec

    if export is None:
        return None
    if export_out is None:
        raise ElicitError("--export needs --export-out")
    return ExportSpec(
        format=export,  # type: ignore[arg-type]
        out=str(export_out),
        mask_key=mask_key,
        source=None if source is None else str(source),
        overwrite=overwrite,
    )
