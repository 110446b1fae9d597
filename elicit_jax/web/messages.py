"""The JSON messages the server sends a page (see :mod:`elicit_jax.web.protocol`).

Each builder returns the message as text. Arrays become lists and non-finite numbers
``null``, so the page never parses a NaN. What a naive-mode operator must not see (the
rule, indicators, verdicts and feedback) is never built for them: the session emits no
indicator or review events in naive mode, and :func:`welcome` leaves the rule out.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from elicit_jax.elicit.events import Event, PromptEvent, ReviewEvent, event_to_dict, to_jsonable
from elicit_jax.web.protocol import PROTOCOL_VERSION


def _finite(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    return value


def dump(kind: str, **fields: Any) -> str:
    """``{"type": kind, **fields}`` as JSON (numpy values converted, NaN as null)."""
    return json.dumps(_finite(to_jsonable({"type": kind, **fields})), allow_nan=False)


def welcome(name: str, setup: Any, resumed: bool, period: float) -> str:
    """Who the page is and what the session is (sent first, and again on every reattach)."""
    from elicit_jax.elicit.inputs import task_action_names
    from elicit_jax.elicit.light import rule_words, whole

    c, task = setup.config, setup.task
    informed = c.mode == "informed"
    horizon = int(task.config.horizon)
    return dump(
        "welcome",
        protocol=PROTOCOL_VERSION,
        name=name,
        task=task.name,
        mode=c.mode,
        dagger=c.dagger,
        control_hz=round(1.0 / period, 6),
        horizon=horizon,
        action_names=list(task_action_names(task)),
        practice=c.practice,
        prompt=c.prompt if c.mode == "informed" else 0,
        demos=c.demos,
        max_episodes=c.episode_limit,
        rule=setup.rule.describe() if informed else "",
        rule_words=rule_words(setup.rule, horizon) if informed else "",
        allowed_at_horizon=whole(setup.rule.allowed(horizon)) if informed else None,
        resumed=resumed,
    )


def scene(task: Any) -> str:
    """The scene to build once (:func:`elicit_jax.web.scene.scene_description`)."""
    from elicit_jax.web.scene import scene_description

    return dump("scene", **scene_description(task.mj_model, task.name))


def event(e: Event) -> str:
    """A session event as data (:func:`~elicit_jax.elicit.events.event_to_dict`)."""
    return dump("event", event=event_to_dict(e))


def prompt(e: PromptEvent) -> str:
    """The prompt's base demonstrations (their poses follow as clips, role 0, by index)."""
    episodes = [
        {
            "index": i,
            "base_episode": p.base_episode,
            "mean_likelihood": p.mean_likelihood,
            "length": len(p.action),
            "exact": p.init_seed >= 0,
        }
        for i, p in enumerate(e.episodes)
    ]
    return dump("prompt", message=e.message, episodes=episodes)


def review(e: ReviewEvent, record: Any, allowed: float | None = None) -> str:
    """The verdict and feedback; each window carries M over its steps (clips follow), and
    ``indicators`` holds ``[step, M, incompatible]`` of every scored step of the episode;
    ``allowed_steps``: the most incompatible steps the rule allows at this length."""
    steps = np.flatnonzero(record.scored)
    windows = []
    for i, w in enumerate(e.feedback):
        idx = steps[w.start : w.stop]
        windows.append(
            {
                **to_jsonable(w),
                "index": i,
                "episode_steps": idx,
                "m": record.compatibility[idx],
            }
        )
    return dump(
        "review",
        episode=e.episode,
        verdict=e.verdict,
        incompatible=e.incompatible,
        scored=e.scored,
        fraction=e.fraction,
        allowed_steps=allowed,
        rule=e.rule,
        text=e.text,
        windows=windows,
        indicators=[
            [int(t), float(record.compatibility[t]), float(record.incompatible[t])] for t in steps
        ],
    )


def indicators(items: list[list[Any]], last: Event | None = None) -> str:
    """The current episode's indicator history ``[[step, M, incompatible, light], ...]`` and its
    last indicator event (its live state: red steps, allowance), sent on a reattach so a
    reloaded page shows what it showed before."""
    return dump("indicators", items=items, last=None if last is None else event_to_dict(last))


def state(**fields: Any) -> str:
    """Where the operator's session stands (the page picks its screen from this)."""
    return dump("state", **fields)


def error(message: str) -> str:
    return dump("error", message=message)


def history(rows: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per finished episode: index, kind, verdict and length (nothing a naive page hides)."""
    return [
        {
            "index": r.get("index"),
            "kind": r.get("episode_kind"),
            "verdict": r.get("verdict"),
            "length": r.get("length"),
        }
        for r in rows
    ]
