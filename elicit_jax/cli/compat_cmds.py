"""Compatibility commands: score, fit-thresholds, filter, map."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from elicit_jax.cli.app import COMPAT, app, check_seed
from elicit_jax.cli.outputs import OVERWRITE, drop_reason, note_duplicates
from elicit_jax.cli.threshold_options import ETA, LAMBDA, THRESHOLDS, thresholds_from_flags
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.compat.measures import ScoreConfig


@app.command(rich_help_panel=COMPAT)
def score(
    policy: Path = typer.Option(..., "--policy", help="Base policy checkpoint or run directory."),
    demos: Path = typer.Option(..., "--demos", help="Demonstrations to score (demos artifact)."),
    out: Path = typer.Option(..., "-o", "--out", help="Scores artifact to write (.parquet)."),
    thresholds: Path | None = THRESHOLDS,
    lambda_: float | None = LAMBDA,
    eta: float | None = ETA,
    preset: str | None = typer.Option(
        None,
        "--preset",
        help="Paper thresholds: square-nut, round-nut or hammer-drawer. Default: the preset of "
        "the demos' task if it has one, else square-nut's, borrowed (with a warning).",
    ),
    likelihood: str = typer.Option(
        "ensemble-mean", "--likelihood", help="ensemble-mean (paper) or member-average (code)."
    ),
    ddof: int = typer.Option(0, "--ddof", help="Std convention of novelty: 0 paper, 1 code."),
    action_scale: str = typer.Option(
        "none",
        "--action-scale",
        help="none (paper: raw action units) or std (each dim divided by the training actions' "
        "std; constant dims left out).",
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

    (lam, et), source = _score_thresholds(demos, thresholds, lambda_, eta, preset, action_scale)
    check_outputs([out, episodes_path(out)], [demos, policy, thresholds], overwrite=overwrite)
    config = ScoreConfig(
        likelihood=likelihood,  # type: ignore[arg-type]
        ddof=ddof,
        lambda_=lam,
        eta=et,
        accept_fraction=accept_fraction,
        chunk_size=chunk_size,
        action_scale=action_scale,
        dropout_samples=dropout_samples,
        dropout_seed=dropout_seed,
    )
    which_: str | int = int(which) if which.isdigit() else which
    _score_and_show(policy, demos, out, config, which_, seed, source)


def _score_and_show(
    policy: Path,
    demos: Path,
    out: Path,
    config: ScoreConfig,
    which: str | int,
    seed: int | None,
    source: str | None,
) -> None:
    """Load the checkpoint, warn about a one-member policy, score with a progress bar and
    print a table per operator."""
    from rich.console import Console

    from elicit_jax.cli.info_compat import print_operator_table
    from elicit_jax.compat.score_file import one_member_note, score_file
    from elicit_jax.compat.show import scoring_bar
    from elicit_jax.policy.checkpoint import load_policy

    loaded = load_policy(policy, which, seed=seed)
    note = one_member_note(loaded, config)
    if note:
        Console(stderr=True).print(f"[yellow]warning:[/] {note}", soft_wrap=True)
    result = score_file(
        loaded,
        demos,
        out,
        config,
        policy_path=policy,
        policy_info={"which": which, "seed": seed},
        progress=scoring_bar,
        thresholds_source=source,
    )
    print_operator_table(
        result.episodes,
        title=f"{demos.name} scored (λ={config.lambda_:.3g}, η={config.eta:.3g}, "
        f"reject > {100 * config.accept_fraction:g}% incompatible)",
    )


def _score_thresholds(
    demos: Path,
    thresholds: Path | None,
    lam: float | None,
    eta: float | None,
    preset: str | None,
    action_scale: str,
) -> tuple[tuple[float, float], str]:
    """``score``'s (λ, η) and where they came from, in the units of ``action_scale``."""
    given = thresholds_from_flags(thresholds, lam, eta, preset, action_scale)
    resolved, source = (None, "") if given is None else (given.pair, given.source)
    if resolved is None:
        resolved, source = _task_preset(demos, quiet=action_scale == "std")
        if action_scale == "std":
            source = _std_placeholder(source)
    elif action_scale == "std" and thresholds is None:
        typer.echo("thresholds: --lambda/--eta read in std-scaled units", err=True)
        source += " (std-scaled units)"
    return resolved, source


def _std_placeholder(task_source: str) -> str:
    """Said (and recorded) when ``--action-scale std`` scores without thresholds: the
    task's preset is in raw units, so M and accept/reject only hold its values as a stand-in."""
    typer.echo(
        "warning: --action-scale std: the paper presets are in raw action units, so M and "
        "accept/reject in this file are placeholders, not verdicts; ℓ and ν are std-scaled. "
        "Fit thresholds on these scores (elicit-jax fit-thresholds) and pass --thresholds to "
        "filter and map.",
        err=True,
    )
    return f"placeholder, not valid for --action-scale std scores: {task_source} (raw units)"


def _scores_scale(scores: Path) -> str:
    from elicit_jax.artifact import read_header

    return str(read_header(scores).get("config", {}).get("action_scale", "none"))


def _task_preset(demos: Path, quiet: bool = False) -> tuple[tuple[float, float], str]:
    """(λ, η) and their source when none are given: the paper preset of the demos' task, or
    square-nut's values, borrowed and marked as such (said on stderr unless ``quiet``)."""
    from elicit_jax.artifact import read_header
    from elicit_jax.compat.measures import PRESETS, preset_for_task

    task = read_header(demos).get("task", "unknown")
    name = preset_for_task(task)
    if name is not None:
        lam, eta = PRESETS[name]
        if not quiet:
            typer.echo(
                f"thresholds: paper preset {name} (λ={lam}, η={eta}) for task {task}", err=True
            )
        return (lam, eta), f"preset {name} (task {task})"
    lam, eta = PRESETS["square-nut"]
    if not quiet:
        typer.echo(
            f"warning: task '{task}' has no paper preset; M and accept/reject use square-nut's "
            f"λ={lam}, η={eta}, borrowed, not fitted for it. Fit your own "
            "(elicit-jax fit-thresholds) and pass --thresholds to filter and map.",
            err=True,
        )
    return (lam, eta), f"borrowed: square-nut preset, not fitted for task {task} (it has no preset)"


@app.command("fit-thresholds", rich_help_panel=COMPAT)
def fit_thresholds_cmd(
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
    lambda_: float | None = typer.Option(
        None,
        "--lambda",
        help="Hand-set λ instead of fitting (with --eta); contrast sets, if given, only "
        "evaluate it.",
    ),
    eta: float | None = typer.Option(None, "--eta", help="Hand-set η (with --lambda)."),
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
    from elicit_jax.artifact import check_outputs
    from elicit_jax.compat.fit import FitJob, fit_scores_file
    from elicit_jax.compat.show import print_report
    from elicit_jax.compat.thresholds import FitConfig

    check_outputs([out], [scores], overwrite=overwrite)
    job = FitJob(
        compatible=compatible,
        incompatible=incompatible,
        fit=FitConfig(accept_fraction=accept_fraction, grid_size=grid_size),
        lambda_=lambda_,
        eta=eta,
        force=force,
        base=() if base is None else (str(base),),
    )
    fit_scores_file(scores, out, job, show=print_report)


@app.command("filter", rich_help_panel=COMPAT)
def filter_cmd(
    scores: Path | None = typer.Option(
        None, "--scores", help="Scores of --demos (deminf/demo-score: only with --rate m)."
    ),
    demos: Path = typer.Option(..., "--demos", help="New demonstrations D_new."),
    out: Path = typer.Option(..., "-o", "--out", help="Filtered demos artifact (.parquet)."),
    base: Path | None = typer.Option(None, "--base", help="D_base, kept whole, placed first."),
    level: str = typer.Option("pair", "--level", help="pair or episode."),
    method: str = typer.Option(
        "m",
        "--method",
        help="m | random | shortest | longest | likelihood | novelty | deminf | demo-score | "
        "cupid | quality.",
    ),
    pair_mode: str = typer.Option(
        "renumber", "--pair-mode", help="After dropping pairs: renumber steps or split episodes."
    ),
    thresholds: Path | None = THRESHOLDS,
    lambda_: float | None = LAMBDA,
    eta: float | None = ETA,
    seed: int = typer.Option(0, "--seed", help="Seed of the random baseline.", callback=check_seed),
    export: str | None = typer.Option(
        None, "--export", help="Also export kept episodes: robomimic (mask) or lerobot."
    ),
    export_out: Path | None = typer.Option(
        None, "--export-out", help="robomimic: the .hdf5 copy; lerobot: folder or .json list."
    ),
    mask_key: str | None = typer.Option(None, "--mask-key", help="robomimic: new filter key."),
    source: Path | None = typer.Option(
        None, "--source", help="Original dataset for --export (default: recorded at import)."
    ),
    rate: str = typer.Option(
        "own", "--rate", help="deminf/demo-score: own (their own cut) or m (M-filter's amount)."
    ),
    drop_fraction: float = typer.Option(
        0.2, "--drop-fraction", help="deminf's own cut: lowest fraction of demos."
    ),
    policy: Path | None = typer.Option(
        None, "--policy", help="demo-score: training run to roll out (trained on the data)."
    ),
    task: str | None = typer.Option(
        None, "--task", help="demo-score: task (default: the demos' task)."
    ),
    rollouts: int = typer.Option(100, "--rollouts", help="demo-score: rollouts per checkpoint."),
    policy_seed: int | None = typer.Option(
        None, "--policy-seed", help="demo-score: training seed of --policy (default: its first)."
    ),
    trajectories: Path | None = typer.Option(
        None, "--trajectories", help="cupid: evaluate --trajectories of --policy (noisy)."
    ),
    checkpoint: str = typer.Option(
        "best", "--checkpoint", help="cupid: the checkpoint of --policy that was rolled out."
    ),
    proj_dim: int = typer.Option(512, "--proj-dim", help="cupid: gradient projection dim."),
    overwrite: bool = OVERWRITE,
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
    """
    from elicit_jax.compat.filtering import ExportSpec, FilterConfig, filter_demos

    scale = _scores_scale(scores) if scores is not None else None
    given = thresholds_from_flags(thresholds, lambda_, eta, action_scale=scale)
    resolved = None if given is None else given.pair
    inputs = [scores, demos, base, policy, source, thresholds, trajectories]
    _check_filter_outputs(out, method, export_out, overwrite, inputs)
    if method in CURATORS:
        from elicit_jax.cli.curation_cmds import CurateArgs, curate

        if export is not None:
            raise ElicitError("--export works with the M-filter and its baselines only")
        curate(CurateArgs(method, demos, out, base, level, scores, resolved, rate, drop_fraction,
                          policy, task, rollouts, policy_seed, trajectories, checkpoint,
                          proj_dim))  # fmt: skip
        return
    if scores is None:
        raise ElicitError(f"--method {method} filters by compatibility scores: give --scores")
    config = FilterConfig(
        level=level,  # type: ignore[arg-type]
        method=method,
        pair_mode=pair_mode,  # type: ignore[arg-type]
        lambda_=resolved[0] if resolved else None,
        eta=resolved[1] if resolved else None,
        seed=seed,
    )
    spec = None
    if export is not None:
        if export_out is None:
            raise ElicitError("--export needs --export-out")
        spec = ExportSpec(
            format=export,  # type: ignore[arg-type]
            out=str(export_out),
            mask_key=mask_key,
            source=None if source is None else str(source),
            overwrite=overwrite,
        )
    r = filter_demos(scores, demos, out, config, base_path=base, export=spec)
    note_duplicates(r.duplicates)
    why = drop_reason(r.reason, r.duplicates)
    typer.echo(
        f"{out}: dropped {r.pairs_dropped}/{r.pairs_in} pairs of D_new "
        f"({r.episodes_in} -> {r.episodes_out} episodes; {why}); log: {r.log_path}"
    )
    if r.export is not None:
        typer.echo(f"exported {r.export.get('episodes')} episodes to {export_out}")


def _check_filter_outputs(
    out: Path, method: str, export_out: Path | None, overwrite: bool, inputs: list
) -> None:
    """Every file ``filter`` writes (the demos, its drop log or per-demo scores, an export),
    checked by the one output rule before any work."""
    from elicit_jax.artifact import check_outputs
    from elicit_jax.compat.filtering import log_path
    from elicit_jax.curation.select import scores_path_for
    from elicit_jax.data.export import is_lerobot_dataset

    outs = [out, log_path(out)] + ([scores_path_for(out)] if method in CURATORS else [])
    check_outputs(outs, inputs, overwrite=overwrite)
    check_outputs([export_out], inputs, overwrite=overwrite, replaceable=is_lerobot_dataset)


CURATORS = ("deminf", "demo-score", "cupid", "quality")


@app.command("map", rich_help_panel=COMPAT)
def map_cmd(
    scores: Path = typer.Option(..., "--scores", help="Scores artifact."),
    out: Path = typer.Option(..., "-o", "--out", help="map.png or map.html (interactive)."),
    thresholds: Path | None = THRESHOLDS,
    lambda_: float | None = LAMBDA,
    eta: float | None = ETA,
    axis: str = typer.Option(
        "likelihood-error", "--axis", help="likelihood-error (ℓ) or neg-likelihood-error (−ℓ)."
    ),
    overwrite: bool = OVERWRITE,
) -> None:
    """Draw the compatibility map: likelihood vs novelty per operator, threshold box.

    Example: elicit-jax map --scores scores.parquet -o map.png
    """
    from elicit_jax.artifact import check_outputs
    from elicit_jax.compat.maps import map_scores_file

    given = thresholds_from_flags(thresholds, lambda_, eta, action_scale=_scores_scale(scores))
    resolved = None if given is None else given.pair
    check_outputs([out], [scores, thresholds], overwrite=overwrite)
    lam, et = map_scores_file(scores, out, *(resolved if resolved else (None, None)), axis=axis)
    typer.echo(f"{out}: map with λ={lam:.3g}, η={et:.3g}")
