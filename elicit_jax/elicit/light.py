"""The live light: one state per scored step that never contradicts the episode's verdict.

The rule judges a finished demonstration by its red steps (incompatible pairs, M = 0) against
its scored length (:class:`~elicit_jax.elicit.rules.AcceptRule`). While the episode runs its
length is not known, so the live state reports two things that are true at every step:

* the **allowance at the horizon** — the most red steps an episode of the task's full length
  may hold (``floor(5% × horizon)``, fixed for the whole episode; the ``count`` rule's N). An
  episode is never longer than its horizon, so once the red steps exceed it the episode
  **can no longer be accepted**, whatever happens next (:attr:`LiveState.doomed`);
* the **verdict if it ended now** with the task done (:attr:`LiveState.accept_now`): the rule
  applied to the red steps and scored length so far — exactly the final verdict's arithmetic
  when the episode does end here.

Each step also gets a light, the step's own state, most pressing first:

* ``red`` — the step does not fit (M = 0: ``ℓ > λ`` where the robot has data; the rule
  counts it);
* ``idle`` — the operator is not acting (no motion, the gripper unchanged): never shown as
  green;
* ``unfamiliar`` — the robot has no data here (``ν ≥ η``: the ensemble disagrees, and the
  method sets M = 1, so the step is never red; it is not evidence that the motion fits);
* ``fits`` — the robot would move like this here (``ν < η`` and M > 0).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

LIGHTS = ("red", "idle", "unfamiliar", "fits")
STILL = 1e-3
"""A motion command below this (in the action's [-1, 1] units) is no motion."""


def whole(allowed: float) -> int:
    """Whole red steps a rule's allowance permits (it rejects strictly above ``allowed``)."""
    return math.floor(allowed + 1e-9)


@dataclasses.dataclass(frozen=True)
class LiveState:
    """The live indicator after one scored step (see the module docstring).

    Attributes:
      light: ``red``, ``idle``, ``unfamiliar`` or ``fits`` (this step).
      red: red steps of the episode so far.
      scored: scored steps of the episode so far.
      horizon: the task's horizon (the longest an episode can be).
      allowed: whole red steps an episode of the horizon's length may hold (fixed).
      left: red steps the episode may still have at the horizon (``allowed − red``, ≥ 0).
      doomed: more red steps than ``allowed``: the episode can no longer be accepted.
      accept_now: the rule accepts the episode if it ended now with the task done.
      allowed_now: whole red steps the rule allows at the scored length so far.
    """

    light: str
    red: int
    scored: int
    horizon: int
    allowed: int
    left: int
    doomed: bool
    accept_now: bool
    allowed_now: int


def live_state(
    rule: Any,
    horizon: int,
    red: int,
    scored: int,
    *,
    incompatible: bool,
    unfamiliar: bool,
    idle: bool,
) -> LiveState:
    """The live state after a scored step.

    Args:
      rule: the session's :class:`~elicit_jax.elicit.rules.AcceptRule`.
      horizon: the task's horizon in control steps.
      red: red (incompatible) steps so far, this one included.
      scored: scored steps so far, this one included.
      incompatible: this step is red (M = 0).
      unfamiliar: this step's novelty is at or above η (M = 1 by the method's rule).
      idle: the operator did not act at this step (:func:`is_idle`).
    """
    allowed = whole(rule.allowed(horizon))
    light = "red" if incompatible else "idle" if idle else "unfamiliar" if unfamiliar else "fits"
    return LiveState(
        light=light,
        red=int(red),
        scored=int(scored),
        horizon=int(horizon),
        allowed=allowed,
        left=max(0, allowed - int(red)),
        doomed=bool(rule.rejects(red, horizon)),
        accept_now=not rule.rejects(red, scored),
        allowed_now=whole(rule.allowed(scored)),
    )


def is_idle(action: np.ndarray, previous: np.ndarray | None, names: Sequence[str]) -> bool:
    """The operator did not act: no motion command, and the gripper as it was.

    Args:
      action: (A,) the operator's action this step.
      previous: (A,) the action applied at the step before, or None (the first step).
      names: the action's dimension names (``gripper`` is a held open/closed command, not a
        motion: holding it is idle, changing it is not).
    """
    a = np.asarray(action, np.float64)
    grip = np.array(["grip" in str(n) for n in names][: len(a)] + [False] * (len(a) - len(names)))
    if np.any(np.abs(a[~grip]) >= STILL):
        return False
    if previous is None or not grip.any():
        return True
    return bool(np.all(np.abs(a[grip] - np.asarray(previous, np.float64)[grip]) < STILL))


def rule_words(rule: Any, horizon: int) -> str:
    """The accept rule in plain words, with the allowance at the horizon."""
    allowed = whole(rule.allowed(horizon))
    steps = "step" if allowed == 1 else "steps"
    if rule.count is not None:
        return (
            f"A demonstration is accepted when it completes the task with at most {allowed} red "
            f"{steps}, however long it takes. A step is red when your move is not what the "
            "robot would do there."
        )
    pct = f"{100 * rule.fraction:g}%"
    return (
        f"A demonstration is accepted when it completes the task and at most {pct} of its steps "
        f"are red: at most {allowed} red {steps} in a full {horizon}-step episode, fewer if "
        f"you finish sooner ({pct} of the steps you take). A step is red when your move is "
        "not what the robot would do there; where the robot has no data a step is never red."
    )
