"""The stage kinds an elicitation study adds (:data:`ELICITATION_KINDS`): sessions with
simulated people and the M-filter of a naive session's demonstrations; and what its report
gathers from the filtering pipeline's own kinds (collect, fit-thresholds:
:data:`ELICITATION_GATHER`). Its other stages are the filtering pipeline's: collect, train,
score, fit-thresholds, evaluate.

A session stage runs in its output directory, which is a session directory: a run killed
mid-session resumes it where it stopped (the session's own resume; the person relives the
recorded episodes), and a changed config or input starts it again.
"""

from __future__ import annotations

from typing import Any

from elicit_jax.artifact import atomic_path, write_json
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.elicitation import gather as study_gather
from elicit_jax.pipeline.elicitation.gather import DISTANCE_KEY, PERSON_FILE
from elicit_jax.pipeline.runner import StageContext
from elicit_jax.pipeline.stage_kind import StageKind

# Session fields only known when the stage runs: stand-ins while the settings are validated,
# removed again before they are recorded.
_SET_AT_RUN_TIME = {"policy": "-", "base_demos": "-"}
_META = ("task", "model", "person", "condition")


def _resolve_session(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.compat.thresholds import SESSION_KEYS, Thresholds
    from elicit_jax.elicit.config import SessionConfig

    meta = {k: raw[k] for k in _META if k in raw}
    fields = {k: v for k, v in raw.items() if k not in ("model", "person", "condition")}
    try:
        stand_in = Thresholds(1.0, 1.0, "set when the stage runs: the fitted thresholds")
        config = SessionConfig.from_dict({**fields, **_SET_AT_RUN_TIME}, thresholds=stand_in)
    except ElicitError as e:
        raise ElicitError(f"[session] {e}") from None
    settings = config.to_dict()
    for key in (*_SET_AT_RUN_TIME, *SESSION_KEYS):
        settings.pop(key)
    return {**meta, "session": settings}


def _resolve_filter_session(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.pipeline.stage_config import resolve_filter, resolve_score

    where = {"task": raw["task"], "model": raw["model"]}
    score = resolve_score(
        {**raw["score"], **where, "policy_seed": raw["policy_seed"], "set": "naive"}
    )
    filt = resolve_filter(
        {**raw["filter"], **where, "method": "filtered", "operator": raw["person"]}
    )
    return {**where, "person": raw["person"], "score": score, "filter": filt}


def session_stage(ctx: StageContext) -> None:
    """Run one session of one simulated person (resuming one a killed run left)."""
    from rich.progress import Progress

    from elicit_jax.compat.thresholds import read_thresholds
    from elicit_jax.elicit.config import SessionConfig
    from elicit_jax.elicit.events import EpisodeEndEvent
    from elicit_jax.elicit.people import person_of
    from elicit_jax.elicit.run import run_session
    from elicit_jax.elicit.setup import open_session
    from elicit_jax.pipeline.stages import demos_file

    config = SessionConfig.from_dict(
        {
            **ctx.config["session"],
            "policy": str(ctx.inputs["policy"]),
            "base_demos": str(demos_file(ctx.inputs["base"])),
        },
        thresholds=read_thresholds(ctx.inputs["thresholds"]),
    )
    try:
        setup, operator, _ = open_session(config, ctx.output)
    except ElicitError:  # a session of other settings or inputs: start it again
        setup, operator, _ = open_session(config, ctx.output, overwrite=True)
    label = f"{ctx.config['condition']} {ctx.config['person']}"
    with Progress(console=ctx.console, transient=True) as progress:
        bar = progress.add_task(f"session {label}", total=config.episode_limit)

        def advance(event: Any) -> None:
            if isinstance(event, EpisodeEndEvent):
                progress.update(bar, completed=event.counts.episodes)

        session = run_session(setup, operator, [lambda _s: advance])
    person = person_of(operator)
    if person is None:
        raise ElicitError(f"operator {config.operator!r} is not a simulated person")
    record = person.summary()
    record[DISTANCE_KEY] = {
        "start": distance_from_base(ctx.config["task"], record["start_theta"]),
        "end": distance_from_base(ctx.config["task"], record["theta"]),
    }
    write_json(ctx.output / PERSON_FILE, record)
    c = session.progress.counts
    changes = ", ".join(f"{x['source']} (e{x['episode']})" for x in person.log) or "none"
    theta = " ".join(f"{k}={v:.3g}" for k, v in person.space.named(person.theta).items())
    ctx.console.print(
        f"{label}: {c.accepted}/{c.wanted} accepted, {c.rejected} rejected, {c.failed} failed, "
        f"{c.episodes} episodes; changes: {changes}; θ now {theta}"
    )


def distance_from_base(task: str, theta: dict[str, float]) -> float:
    """How far a person's θ (``{name: value}``) lies from the base operator's, in the
    space's :meth:`~elicit_jax.elicit.people.space.ParamSpace.distance` (the study measures
    it from the base operator's choices; the person never reads them)."""
    import numpy as np

    from elicit_jax.elicit.people.person import BASE_STYLE
    from elicit_jax.elicit.people.space import space_of
    from elicit_jax.sim.operators import full_choices

    space = space_of(task)
    base = space.theta(full_choices(task, BASE_STYLE))
    return round(space.distance(np.array([theta[n] for n in space.names]), base), 4)


def filter_session_stage(ctx: StageContext) -> None:
    """M-filter a naive session's demonstrations: score them with the base policy and drop
    the incompatible pairs (ℓ > λ in a familiar state). Nothing accepted, or every pair
    dropped: no demonstrations file, and the retraining uses D_base alone."""
    import numpy as np

    from elicit_jax.compat.filtering import FilterConfig, drop_mask
    from elicit_jax.compat.measures import config_from_dict
    from elicit_jax.compat.score_file import read_scores, score_file
    from elicit_jax.compat.show import scoring_bar
    from elicit_jax.compat.thresholds import read_thresholds
    from elicit_jax.pipeline.stages import DEMOS_FILE, SCORES_FILE
    from elicit_jax.pipeline.stages_compat import write_filter_output
    from elicit_jax.policy.loaded import load_policy

    thresholds = read_thresholds(ctx.inputs["thresholds"])
    source = ctx.inputs["session"] / DEMOS_FILE
    score_cfg = ctx.config["score"]
    cfg = FilterConfig.from_dict(ctx.config["filter"]["filter"], thresholds)
    counts = {"pairs_in": 0, "pairs_dropped": 0, "episodes_in": 0, "episodes_out": 0}
    with atomic_path(ctx.output) as tmp:
        tmp.mkdir()
        drop, reason = None, "the naive session accepted no demonstrations"
        if source.exists():
            policy = load_policy(
                ctx.inputs["policy"], score_cfg["checkpoint"], seed=score_cfg["policy_seed"]
            ).policy
            score_file(
                policy,
                source,
                tmp / SCORES_FILE,
                config_from_dict(score_cfg["score"], "the session filter's [score] settings"),
                policy_path=ctx.inputs["policy"],
                progress=scoring_bar,
            )
            _, scores = read_scores(tmp / SCORES_FILE)
            drop, reason = drop_mask(scores, cfg)
            counts["pairs_in"], counts["pairs_dropped"] = int(drop.size), int(drop.sum())
            counts["episodes_in"] = int(np.unique(scores["episode"]).size)
        write_filter_output(
            ctx, tmp, tmp / SCORES_FILE, source, cfg, drop, reason, counts, (SCORES_FILE,)
        )


# fmt: off
ELICITATION_KINDS = (
    StageKind(
        "session", session_stage, _resolve_session, ("policy", "base", "thresholds"),
        "sessions/", True, gather={"sessions": study_gather.session_rows},
    ),
    StageKind(
        "filter-session", filter_session_stage, _resolve_filter_session,
        ("session", "policy", "thresholds"), "filtered/", True,
        gather={"session_filters": study_gather.filter_counts},
    ),
)
"""The stage kinds an elicitation study adds to the filtering study's."""

ELICITATION_GATHER = {
    "collect": {
        "base_lengths": study_gather.base_lengths, "base_states": study_gather.base_states,
    },
    "fit-thresholds": {"study_thresholds": study_gather.fitted_thresholds},
}
# fmt: on
"""What an elicitation study's report gathers from the filtering study's stage kinds."""
