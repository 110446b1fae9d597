"""The filtering study's stage kinds (:data:`FILTERING_KINDS`: one
:class:`~elicit_jax.pipeline.stage_kind.StageKind` each) and its curation stage functions.

The other stage functions live in :mod:`~elicit_jax.pipeline.stages_policy` (collect, train,
evaluate), :mod:`~elicit_jax.pipeline.stages_compat` (score, fit, filter, map, λ variants) and
:mod:`~elicit_jax.pipeline.curation_stages` (CUPID, quality flags); configs are resolved in
:mod:`~elicit_jax.pipeline.stage_config`, outputs gathered in
:mod:`~elicit_jax.pipeline.gather_rows`.

Each adapter reads its inputs, builds the library's frozen config from the stage config and
calls ONE library function (``train_policy``, ``score_file``, ``fit_thresholds``,
``filter_demos``, the simulator's collection and evaluation, the map renderer). Stages whose
library writes sibling files (scores + per-episode summary, filtered demos + drop log) get a
directory output, written atomically as a whole. A kind's ``resolve`` turns a stage's raw
overrides into the library's full config, so a changed library default changes the recorded
config and re-runs the stage.
"""

from __future__ import annotations

from elicit_jax.artifact import atomic_path
from elicit_jax.pipeline import gather_rows as gr
from elicit_jax.pipeline import stage_config as sc
from elicit_jax.pipeline.curation_stages import (
    cupid_stage,
    quality_stage,
    resolve_cupid,
    resolve_quality,
)
from elicit_jax.pipeline.gather import ROLLOUTS
from elicit_jax.pipeline.runner import StageContext
from elicit_jax.pipeline.stage_kind import StageKind
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

__all__ = [  # re-exported for the elicitation study's stages
    "DEMOS_FILE",
    "SCORES_FILE",
    "demos_file",
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


# fmt: off
FILTERING_KINDS = (
    StageKind(
        "collect", collect_stage, sc.resolve_collect, outputs="data/", reported=True,
        gather={"lengths": gr.length_rows, "conflicts": gr.conflict_rows},
    ),
    StageKind(
        "train", train_stage, sc.resolve_train, inputs=("demos0", "demos1"), outputs="policies/"
    ),
    StageKind(
        "evaluate", evaluate_stage, sc.resolve_evaluate, ("policy",), "evals/", True,
        gather={ROLLOUTS: gr.rollout_frames},
    ),
    StageKind(
        "score", score_stage, sc.resolve_score, ("policy", "demos0", "demos1", "thresholds"),
        "scores/",
    ),
    StageKind(
        "fit-thresholds", fit_stage, sc.resolve_fit, ("scores",), "thresholds/", True,
        gather={"thresholds": gr.threshold_rows},
    ),
    StageKind(
        "filter", filter_stage, sc.resolve_filter, ("scores", "thresholds", "demos"),
        "filtered/", True, gather={"filters": gr.filter_rows},
    ),
    StageKind(
        "curate", curate_stage, sc.resolve_curate,
        ("episode_scores", "scores", "thresholds", "demos"), "filtered/", True,
        gather={"filters": gr.filter_rows},
    ),
    StageKind(
        "deminf", deminf_stage, sc.resolve_deminf, ("demos0", "demos1"), "curation/", True,
        gather={"curation": gr.curation_rows},
    ),
    StageKind(
        "demo-score", demo_score_stage, sc.resolve_demo_score, ("policy", "demos"),
        "curation/", True, gather={"curation": gr.curation_rows},
    ),
    StageKind(
        "cupid", cupid_stage, resolve_cupid, ("policy", "demos0", "demos1"), "curation/", True,
        gather={"curation": gr.curation_rows},
    ),
    StageKind(
        "quality", quality_stage, resolve_quality, ("demos0", "demos1"), "curation/", True,
        gather={"curation": gr.curation_rows},
    ),
    StageKind(
        "lambda-point", lambda_point_stage, None, ("thresholds",), "thresholds/", True,
        gather={"lambda_points": gr.lambda_points},
    ),
    StageKind(
        "lambda-valley", lambda_valley_stage, None, ("thresholds", "scores:*"), "thresholds/",
        True, gather={"thresholds": gr.valley_rows},
    ),
    StageKind(
        "map", map_stage, None, ("thresholds", "scores:*"), "maps/", True, side_by_side=True,
        gather={"maps": gr.map_figures},
    ),
)
# fmt: on
"""The stage kinds of the filtering study (the elicitation study reuses them and adds its
own, :data:`elicit_jax.pipeline.elicitation.stages.ELICITATION_KINDS`; each study's report
stage kind is added by :mod:`elicit_jax.pipeline.study_kinds`)."""
