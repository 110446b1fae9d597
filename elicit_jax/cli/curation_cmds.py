"""Curation commands: ``quality``, and the curation methods of ``filter`` (deminf,
demo-score, cupid, quality)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from elicit_jax.cli.app import COMPAT, app
from elicit_jax.cli.outputs import OVERWRITE, drop_reason
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.compat.thresholds import Thresholds


@dataclasses.dataclass(frozen=True)
class CurateArgs:
    """The ``filter`` options a curation method reads."""

    method: str
    demos: Path
    out: Path
    base: Path | None
    level: str
    scores: Path | None
    thresholds: Thresholds | None
    rate: str
    drop_fraction: float
    policy: Path | None
    task: str | None
    rollouts: int
    policy_seed: int | None
    trajectories: Path | None = None
    checkpoint: str = "best"
    proj_dim: int = 512


def curate(a: CurateArgs) -> None:
    """``filter --method deminf|demo-score|cupid|quality``: build the config, make ONE
    library call, print."""
    from elicit_jax.artifact import read_header
    from elicit_jax.cli.outputs import note_duplicates
    from elicit_jax.curation.cupid import CupidConfig
    from elicit_jax.curation.deminf import DemInfConfig
    from elicit_jax.curation.demo_score import DemoScoreConfig, at_chance
    from elicit_jax.curation.select import CurateConfig, curate_file, scores_path_for

    if a.level not in ("pair", "episode"):
        raise ElicitError(f"unknown level '{a.level}' (choose pair or episode)")
    config = CurateConfig(
        method=a.method,
        deminf=DemInfConfig(drop_fraction=a.drop_fraction),
        demo_score=DemoScoreConfig(
            task=a.task or str(read_header(a.demos).get("task", "")),
            rollouts=a.rollouts,
            policy_seed=a.policy_seed,
        ),
        cupid=CupidConfig(proj_dim=a.proj_dim, checkpoint=a.checkpoint, policy_seed=a.policy_seed),
    )
    result, per_demo = curate_file(
        config,
        a.demos,
        a.out,
        rate=a.rate,  # type: ignore[arg-type]
        level=a.level,  # type: ignore[arg-type]
        scores_path=a.scores,
        thresholds=a.thresholds,
        base_path=a.base,
        policy_path=a.policy,
        progress=lambda epoch, rate_: typer.echo(
            f"demo-score: checkpoint {epoch}: {100 * rate_:.0f}% of rollouts succeeded"
        ),
        trajectories_path=a.trajectories,
    )
    note_duplicates(result.duplicates)
    if not per_demo.trusted:
        typer.echo(f"warning: {a.method} had no signal: {per_demo.report.get('why')}", err=True)
    elif a.method == "demo-score" and at_chance(per_demo.report):
        acc = per_demo.report["validation_balanced_accuracy"]
        typer.echo(
            f"warning: demo-score's classifier is no better than chance on held-out rollouts "
            f"(balanced accuracy {acc:.2f}): its ranking of the demos carries no signal",
            err=True,
        )
    if a.method == "cupid" and per_demo.trusted:
        r = per_demo.report
        typer.echo(
            f"cupid: {r['rollouts']} rollouts ({r['rollout_successes']} successes, action "
            f"noise {r['action_noise']:g}); {r['negative_demos']} demos of negative influence"
        )
    why = drop_reason(result.reason, result.duplicates)
    typer.echo(
        f"{a.out}: dropped {result.pairs_dropped}/{result.pairs_in} pairs of D_new "
        f"({result.episodes_in} -> {result.episodes_out} episodes; {why}); "
        f"log: {result.log_path}; per-demo scores: {scores_path_for(a.out)}"
    )


@app.command("quality", rich_help_panel=COMPAT)
def quality_cmd(
    demos: Path = typer.Argument(..., help="A demos artifact (imported or collected)."),
    out: Path = typer.Option(..., "-o", "--out", help="Per-episode quality Parquet."),
    z_threshold: float = typer.Option(3.5, "--z", help="Robust z-score that flags an outlier."),
    gripper_dim: int = typer.Option(-1, "--gripper-dim", help="Gripper action dim (-1: last)."),
    no_gripper: bool = typer.Option(False, "--no-gripper", help="The actions have no gripper."),
    spike_jump: float = typer.Option(
        0.5, "--spike-jump", help="Step-to-step jump that is a spike (action units)."
    ),
    idle_eps: float = typer.Option(
        0.02, "--idle-eps", help="Max-norm below which a motion action is idle (action units)."
    ),
    overwrite: bool = OVERWRITE,
) -> None:
    """Per-episode quality metrics with outlier flags: duration, jerk, idle fraction, action
    spikes, gripper chatter, action variance and state distance (docs/curation.md).

    Each metric gets a robust (MAD-based) z-score over the file's episodes; an episode at or
    above --z is flagged, with a one-line reason. `filter --method quality` drops flagged ones.
    --spike-jump and --idle-eps are in the actions' own units (defaults for actions in [-1, 1]).

    Example: elicit-jax quality demos.parquet -o quality.parquet
    """
    import numpy as np
    from rich.console import Console
    from rich.table import Table

    from elicit_jax.artifact import check_outputs
    from elicit_jax.curation.quality import METRICS, QualityConfig, quality_file

    check_outputs([out], [demos], overwrite=overwrite)
    config = QualityConfig(
        z_threshold=z_threshold,
        gripper_dim=None if no_gripper else gripper_dim,
        spike_jump=spike_jump,
        idle_eps=idle_eps,
    )
    q = quality_file(demos, out, config)
    console = Console()
    table = Table(title=f"{demos}: {len(q.episode)} episodes, {int(q.flagged.sum())} flagged")
    for col in ("metric", "median", "max", "flagged"):
        table.add_column(col, justify="left" if col == "metric" else "right")
    for name in METRICS:
        v = q.metrics[name]
        table.add_row(name, f"{np.median(v):.3g}", f"{v.max():.3g}", str(int(q.flags[name].sum())))
    console.print(table)
    for i in [int(i) for i in q.flagged.nonzero()[0][:20]]:
        console.print(f"episode {q.episode[i]} ({q.operator[i]}): {q.reason[i]}")
    console.print(f"wrote {out}")


@app.command("review", rich_help_panel=COMPAT)
def review_cmd(
    demos: Path = typer.Argument(..., help="A demos artifact to review."),
    scores: Path | None = typer.Option(None, "--scores", help="Compatibility scores of DEMOS."),
    quality: Path | None = typer.Option(None, "--quality", help="elicit-jax quality of DEMOS."),
    out: Path | None = typer.Option(
        None, "-o", "--out", help="Review folder (flags, exports); default DEMOS.review/."
    ),
    port: int = typer.Option(0, "--port", help="Port on 127.0.0.1 (0: any free one)."),
) -> None:
    """Review episodes in the browser: sort by M, quality flags or operator, replay one with
    its M strip, flag/unflag episodes with a reason, and write the kept ones as a demos
    artifact (OUT/kept.parquet) and a robomimic mask or LeRobot episode list.

    The page is served on 127.0.0.1 with an access token (in the printed URL). The flags are
    kept in OUT/review.json, so a review can be resumed.

    Example: elicit-jax review demos.parquet --scores scores.parquet --quality quality.parquet
    """
    from elicit_jax.artifact import refuse_overwriting_inputs
    from elicit_jax.curation.review import Review, ReviewConfig
    from elicit_jax.web.review import serve_review

    if not 0 <= port <= 65535:
        raise ElicitError(f"--port must be in 0..65535, got {port}")
    folder = out or demos.with_name(demos.name.removesuffix(".parquet") + ".review")
    refuse_overwriting_inputs([folder], [demos, scores, quality])
    config = ReviewConfig(
        demos=str(demos),
        out=str(folder),
        scores=None if scores is None else str(scores),
        quality=None if quality is None else str(quality),
    )
    serve_review(Review(config), port, echo=typer.echo)
