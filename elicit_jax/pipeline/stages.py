"""The real stage functions: thin adapters from a :class:`StageContext` to the library.

This module holds the curation stages and the report, and the registry of every stage kind;
the others live in :mod:`~elicit_jax.pipeline.stages_policy` (collect, train, evaluate) and
:mod:`~elicit_jax.pipeline.stages_compat` (score, fit, filter, map, λ variants); configs are
resolved in :mod:`~elicit_jax.pipeline.stage_config`.

Each adapter reads its inputs, builds the library's frozen config from the stage config and
calls ONE library function (``train_policy``, ``score_file``, ``fit_thresholds``,
``filter_demos``, the simulator's collection and evaluation, the map renderer). Stages whose
library writes sibling files (scores + per-episode summary, filtered demos + drop log) get a
directory output, written atomically as a whole. :func:`resolve_config` turns a stage's raw
overrides into the library's full config, so a changed library default changes the recorded
config and re-runs the stage.
"""

from __future__ import annotations

from elicit_jax.artifact import atomic_path
from elicit_jax.pipeline.curation_stages import cupid_stage, quality_stage
from elicit_jax.pipeline.runner import StageContext, StageFn
from elicit_jax.pipeline.stage_config import resolve_config
from elicit_jax.pipeline.stages_compat import (
    filter_stage,
    fit_stage,
    lambda_point_stage,
    lambda_valley_stage,
    map_stage,
    score_stage,
    write_filter_header,
)
from elicit_jax.pipeline.stages_policy import (
    DEMOS_FILE,
    SCORES_FILE,
    collect_stage,
    demos_file,
    evaluate_stage,
    train_stage,
)

__all__ = [  # re-exported for the elicitation study's stages and the run planner
    "DEMOS_FILE",
    "SCORES_FILE",
    "demos_file",
    "real_registry",
    "resolve_config",
    "train_stage",
]


def deminf_stage(ctx: StageContext) -> None:
    """DemInf scores of one D_new, estimated over D_base ∪ D_new."""
    from elicit_jax.curation.deminf import DemInfConfig, deminf_scores
    from elicit_jax.curation.episodes import write_episode_scores
    from elicit_jax.data.demos import read_demos

    cfg = DemInfConfig(**ctx.config["deminf"])
    scores = deminf_scores(read_demos(ctx.inputs["demos1"]), read_demos(ctx.inputs["demos0"]), cfg)
    write_episode_scores(ctx.output, scores, config=dict(ctx.config), inputs=dict(ctx.inputs))


def demo_score_stage(ctx: StageContext) -> None:
    """Demo-SCORE scores of one D_new from rollouts of its naive policy's checkpoints."""
    from elicit_jax.curation.demo_score import DemoScoreConfig, demo_score_scores
    from elicit_jax.curation.episodes import write_episode_scores
    from elicit_jax.data.demos import read_demos

    raw = dict(ctx.config["demo_score"])
    cfg = DemoScoreConfig(**raw)
    scores = demo_score_scores(
        ctx.inputs["policy"],
        read_demos(ctx.inputs["demos"]),
        cfg,
        progress=lambda epoch, rate: ctx.console.print(
            f"  demo-score rollouts, epoch {epoch}: {100 * rate:.0f}% success"
        ),
    )
    inputs = {"policy": ctx.inputs["policy"] / "artifact.json", "demos": ctx.inputs["demos"]}
    write_episode_scores(ctx.output, scores, config=dict(ctx.config), inputs=inputs)


def curate_stage(ctx: StageContext) -> None:
    """Cut one D_new by DemInf / Demo-SCORE scores, at the method's own rule or at the
    M-filter's budget under the fitted thresholds; same output layout as ``filter``."""
    from elicit_jax.compat.thresholds import read_thresholds
    from elicit_jax.curation.episodes import OwnRule, read_episode_scores
    from elicit_jax.curation.select import curate_demos, matched_rule

    cfg = ctx.config
    thresholds = read_thresholds(ctx.inputs["thresholds"])
    scores = read_episode_scores(ctx.inputs["episode_scores"])
    if cfg["rate"] == "m":
        rule = matched_rule(
            ctx.inputs["scores"] / SCORES_FILE, cfg["level"], thresholds, cfg["accept_fraction"]
        )
    else:
        rule = OwnRule(cfg["drop_fraction"])
    with atomic_path(ctx.output) as tmp:
        tmp.mkdir()
        result = curate_demos(
            scores,
            ctx.inputs["demos"],
            tmp / DEMOS_FILE,
            rule,
            config=dict(cfg),
            inputs={"episode_scores": ctx.inputs["episode_scores"]},
            allow_empty=True,
        )
        files = [] if result.out_path is None else [DEMOS_FILE, result.log_path.name]
        reason = result.reason if files else result.reason + "; the retraining uses D_base alone"
        counts = {"pairs_in": result.pairs_in, "pairs_dropped": result.pairs_dropped}
        counts |= {"episodes_in": result.episodes_in, "episodes_out": result.episodes_out}
        write_filter_header(ctx, tmp, thresholds, reason, files, counts, trusted=scores.trusted)


def report_stage(ctx: StageContext) -> None:
    """Gather the run's artifacts and write the Markdown + HTML report."""
    from elicit_jax.pipeline.evidence import round_trip
    from elicit_jax.pipeline.gather import gather
    from elicit_jax.pipeline.report import write_report

    write_report(round_trip(gather(ctx.run_dir)), ctx.output)


def real_registry() -> dict[str, StageFn]:
    """Stage kind -> function, for every stage whose library is wired."""
    return {
        "collect": collect_stage,
        "map": map_stage,
        "evaluate": evaluate_stage,
        "train": train_stage,
        "score": score_stage,
        "fit-thresholds": fit_stage,
        "filter": filter_stage,
        "deminf": deminf_stage,
        "demo-score": demo_score_stage,
        "cupid": cupid_stage,
        "quality": quality_stage,
        "curate": curate_stage,
        "lambda-point": lambda_point_stage,
        "lambda-valley": lambda_valley_stage,
        "report": report_stage,
    }
