"""Compatibility commands: fit-thresholds, filter, map (``score`` is in score_cmd)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from elicit_jax.cli import filter_options as fo
from elicit_jax.cli import threshold_options as th
from elicit_jax.cli.app import COMPAT, app
from elicit_jax.cli.outputs import OVERWRITE, drop_reason, note_duplicates
from elicit_jax.cli.params import with_flags
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.compat.filtering import FilterResult
    from elicit_jax.compat.thresholds import Thresholds


def _scores_scale(scores: Path) -> str:
    """The action scale (``none`` or ``std``) a scores artifact was computed in."""
    from elicit_jax.artifact import read_header

    return str(read_header(scores).get("config", {}).get("action_scale", "none"))


def _applied(scores: Path, given: Thresholds | None, force: bool) -> tuple[Thresholds, list[str]]:
    """:func:`~elicit_jax.compat.threshold_source.applied_thresholds` on a scores file."""
    from elicit_jax.artifact import read_artifact
    from elicit_jax.compat.score import SCHEMA_VERSION, SCORES_KIND
    from elicit_jax.compat.threshold_source import applied_thresholds

    header = read_artifact(scores, SCORES_KIND, SCHEMA_VERSION, what="scores")
    return applied_thresholds(header, scores, given, force)


@app.command("fit-thresholds", rich_help_panel=COMPAT)
@with_flags(th.HAND_SET, before="accept_fraction")
def fit_thresholds_cmd(
    ctx: typer.Context,
    scores: Path = typer.Option(..., "--scores", help="Scores artifact."),
    compatible: str | None = typer.Option(
        None,
        "--compatible",
        help="operator:NAME[,..] | episodes:ID[,..] (ranges: 0-4) | label:COL=VALUE",
    ),
    incompatible: str | None = typer.Option(
        None, "--incompatible", help="Same forms as --compatible."
    ),
    out: Path = typer.Option(..., "-o", "--out", help="thresholds.json to write."),
    accept_fraction: float = typer.Option(0.05, "--accept-fraction", help="The 5% rule."),
    grid_size: int = typer.Option(64, "--grid-size", help="Quantile levels per axis."),
    force: bool = typer.Option(
        False, "--force", help="Write a fit judged meaningless anyway (marked untrustworthy)."
    ),
    base: Path | None = typer.Option(
        None,
        "--base",
        help="The base policy's training demos, to check the thresholds accept them (default: "
        "those in the scores, and the file the checkpoint records).",
    ),
    overwrite: bool = OVERWRITE,
    **flags: Any,
) -> None:
    """Fit (λ, η) so the 5% rule accepts the compatible set and rejects the incompatible one.

    Maximises balanced accuracy over a quantile grid, ties broken by the widest margin
    (docs/thresholds.md). Reports balanced accuracy, margin, leave-one-out accuracy, the
    rejections per operator and whether the fit can be trusted; a meaningless fit (held-out
    decisions at chance, rejecting most of the compatible operators' own demos, or more than
    10% of the base policy's training demos) is refused without --force. The training demos
    are found by content in the scores, else read from --base or the file the policy's
    checkpoint records, and scored under that policy.

    Example: elicit-jax fit-thresholds --scores scores.parquet --compatible operator:base
    --incompatible operator:op4 -o thresholds.json

    Example (hand-set): elicit-jax fit-thresholds --scores scores.parquet --lambda 0.4 --eta
    0.05 -o thresholds.json
    """
    from rich.console import Console

    from elicit_jax.artifact import check_outputs
    from elicit_jax.compat.fit import FitJob, fit_scores_file
    from elicit_jax.compat.show import print_report
    from elicit_jax.compat.threshold_fit import FitConfig

    check_outputs([out], [scores], overwrite=overwrite)
    job = FitJob(
        compatible=compatible,
        incompatible=incompatible,
        fit=FitConfig(accept_fraction=accept_fraction, grid_size=grid_size),
        manual=th.hand_set(ctx.params),
        force=force,
        base=() if base is None else (str(base),),
    )
    console = Console()
    fit_scores_file(scores, out, job, show=lambda header: print_report(header, console))


@app.command("filter", rich_help_panel=COMPAT)
@with_flags(th.APPLY_FLAGS, before="seed")
def filter_cmd(
    ctx: typer.Context,
    scores: Path | None = fo.SCORES,
    demos: Path = fo.DEMOS,
    out: Path = fo.OUT,
    base: Path | None = fo.BASE,
    level: str = fo.LEVEL,
    method: str = fo.METHOD,
    pair_mode: str = fo.PAIR_MODE,
    seed: int = fo.SEED,
    export: str | None = fo.EXPORT,
    export_out: Path | None = fo.EXPORT_OUT,
    mask_key: str | None = fo.MASK_KEY,
    source: Path | None = fo.SOURCE,
    rate: str = fo.RATE,
    drop_fraction: float = fo.DROP_FRACTION,
    policy: Path | None = fo.POLICY,
    task: str | None = fo.TASK,
    rollouts: int = fo.ROLLOUTS,
    policy_seed: int | None = fo.POLICY_SEED,
    trajectories: Path | None = fo.TRAJECTORIES,
    checkpoint: str = fo.CHECKPOINT,
    proj_dim: int = fo.PROJ_DIM,
    overwrite: bool = OVERWRITE,
    **flags: Any,
) -> None:
    """Drop incompatible pairs (ℓ > λ, ν < η) or rejected demos from D_new, or a baseline.

    Baselines drop as many pairs/episodes as the M filter would. Dropped rows and reasons
    go to OUT.dropped.parquet.

    deminf and demo-score (docs/curation.md) score whole demos and drop the lowest: at their
    own cut (--rate own: deminf the lowest --drop-fraction, demo-score below its classifier's
    threshold), or as many pairs (--level pair) / demos (--level episode) as the M-filter
    would (--rate m, needs --scores and thresholds). Per-demo scores go to
    OUT.episode-scores.parquet. cupid (influence on expected return from --policy's noisy
    rollouts --trajectories) drops demos of negative influence; quality drops the demos its
    outlier flags mark (elicit-jax quality).

    With --export robomimic (or lerobot) the kept episodes are also written as a new mask key
    in a copy of the original robomimic file (or a LeRobot dataset / episode list).

    Example: elicit-jax filter --scores scores.parquet --demos new.parquet
    --base base.parquet -o filtered.parquet --level episode

    Example: elicit-jax filter --scores scores.parquet --demos new.parquet -o kept.parquet
    --level episode --export robomimic --mask-key compatible --export-out compatible.hdf5

    Example: elicit-jax filter --method deminf --demos new.parquet --base base.parquet
    -o kept.parquet

    Example: elicit-jax filter --method demo-score --policy runs/naive --demos new.parquet
    -o kept.parquet --rate m --scores scores.parquet --thresholds thresholds.json

    Example: elicit-jax filter --method cupid --policy runs/naive --trajectories steps.parquet
    --demos new.parquet --base base.parquet -o kept.parquet

    Without --thresholds (or --lambda/--eta) the M-filter uses the thresholds the scores were
    judged under, and says which; after fit-thresholds, pass --thresholds thresholds.json.
    """
    from elicit_jax.compat.filtering import filter_demos

    scale = _scores_scale(scores) if scores is not None else None
    given = th.from_params(ctx.params, action_scale=scale)
    if scores is not None and (method not in fo.CURATORS or rate == "m"):
        th.show_applied(_applied(scores, given, flags["force"])[1])
    inputs = [scores, demos, base, policy, source, flags["thresholds"], trajectories]
    fo.check_filter_outputs(out, method, export_out, overwrite, inputs)
    if method in fo.CURATORS:
        from elicit_jax.cli.curation_cmds import CurateArgs, curate

        if export is not None:
            raise ElicitError("--export works with the M-filter and its baselines only")
        curate(CurateArgs(method, demos, out, base, level, scores, given, rate, drop_fraction,
                          policy, task, rollouts, policy_seed, trajectories, checkpoint,
                          proj_dim))  # fmt: skip
        return
    config = fo.filter_config(scores, level, method, pair_mode, given, seed)
    spec = fo.export_spec(export, export_out, mask_key, source, overwrite)
    result = filter_demos(scores, demos, out, config, base_path=base, export=spec)
    _print_filtered(result, out, export_out)


def _print_filtered(r: FilterResult, out: Path, export_out: Path | None) -> None:
    """``filter``'s summary: what was dropped, why, where the log is, what was exported."""
    note_duplicates(r.duplicates)
    why = drop_reason(r.reason, r.duplicates)
    typer.echo(
        f"{out}: dropped {r.pairs_dropped}/{r.pairs_in} pairs of D_new "
        f"({r.episodes_in} -> {r.episodes_out} episodes; {why}); log: {r.log_path}"
    )
    if r.export is not None:
        typer.echo(f"exported {r.export.get('episodes')} episodes to {export_out}")


@app.command("map", rich_help_panel=COMPAT)
@with_flags(th.APPLY_FLAGS, before="axis")
def map_cmd(
    ctx: typer.Context,
    scores: Path = typer.Option(..., "--scores", help="Scores artifact."),
    out: Path = typer.Option(..., "-o", "--out", help="map.png or map.html (interactive)."),
    axis: str = typer.Option(
        "likelihood-error", "--axis", help="likelihood-error (ℓ) or neg-likelihood-error (−ℓ)."
    ),
    overwrite: bool = OVERWRITE,
    **flags: Any,
) -> None:
    """Draw the compatibility map: likelihood vs novelty per operator, threshold box.

    Example: elicit-jax map --scores scores.parquet -o map.png
    """
    from elicit_jax.artifact import check_outputs
    from elicit_jax.compat.maps import map_scores_file

    given = th.from_params(ctx.params, action_scale=_scores_scale(scores))
    check_outputs([out], [scores, flags["thresholds"]], overwrite=overwrite)
    chosen, lines = _applied(scores, given, flags["force"])
    th.show_applied(lines)
    map_scores_file(scores, out, chosen, axis=axis)
    typer.echo(f"{out}: map with λ={chosen.lam:.3g}, η={chosen.eta:.3g}")
