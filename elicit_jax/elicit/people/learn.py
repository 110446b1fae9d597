"""How a person changes its parameters: a generic fit of θ to what it was shown.

:func:`compass_search` is a derivative-free bounded optimiser (coordinate/pattern search: try
each coordinate up and down by its step, take the first improvement, halve the steps when none
helps). :func:`fit_theta` uses it to minimise the imagined action error (teacher forcing, the
person's own calm controller) over the segments the person remembers (:class:`Shown`). Neither
knows anything about the task's styles: the objective is the error on shown actions.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from elicit_jax.elicit.people.imagine import action_error, calm, imagine
from elicit_jax.elicit.people.space import ParamSpace
from elicit_jax.sim.operators import Style

MAX_EVALS = 40
"""Objective evaluations per fit (each imagines every remembered segment)."""
FIRST_STEP = 0.5
"""The search's first step per coordinate, as a fraction of the person's reachable range."""
WATCH_TOL = 0.05
"""Waypoint tolerance (m) of a person's imagination: watching someone else, it counts its own
waypoint reached when the demonstrator passes within this distance (acting: the operator's)."""
WATCH_ALIGN = 1.0
"""Wrist-yaw tolerance (rad) of a person's imagination, likewise (acting: the operator's)."""
MIN_STEP = 0.02
"""The search stops when every step is below this fraction of the reachable range."""


@dataclasses.dataclass(frozen=True)
class Shown:
    """A segment of someone else's demonstration the interface showed, as remembered.

    Attributes:
      states: ``(T, O)`` states from the demonstration's start (the phase machine needs them).
      actions: ``(T, A)`` the actions shown.
      span: the steps compared (the flagged segment; all for a prompt episode).
      weights: ``(A,)`` per-dimension weights (the dimensions feedback named count more).
      source: ``prompt`` or ``feedback``.
    """

    states: np.ndarray
    actions: np.ndarray
    span: slice = dataclasses.field(default_factory=lambda: slice(None))
    weights: np.ndarray | None = None
    source: str = "prompt"


def compass_search(
    f: Callable[[np.ndarray], float],
    x0: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    max_evals: int = MAX_EVALS,
    first_step: float = FIRST_STEP,
) -> tuple[np.ndarray, float, int]:
    """Minimise ``f`` over the box ``[low, high]`` from ``x0`` by compass search.

    Returns:
      ``(x, f(x), evaluations)`` of the best point found.
    """
    x = np.clip(np.asarray(x0, np.float64), low, high)
    fx, evals = f(x), 1
    width = np.maximum(high - low, 1e-12)
    step = first_step * width
    while evals < max_evals and np.any(step > MIN_STEP * width):
        improved = False
        for i in range(len(x)):
            for sign in (1.0, -1.0):
                y = x.copy()
                y[i] = np.clip(x[i] + sign * step[i], low[i], high[i])
                if y[i] == x[i] or evals >= max_evals:
                    continue
                fy = f(y)
                evals += 1
                if fy < fx:
                    x, fx, improved = y, fy, True
                    break
        if not improved:
            step = step * 0.5
    return x, fx, evals


def watching(motor: Style, choices: Mapping[str, Any]) -> Style:
    """The calm style a person imagines with: its own speed and gain, the choices given, and
    loose waypoint tolerances (:data:`WATCH_TOL`, :data:`WATCH_ALIGN`)."""
    loose = dataclasses.replace(motor, tol=WATCH_TOL)
    return calm(loose, {**choices, "align_tol": WATCH_ALIGN})


def imagined_error(
    task: Any, motor: Style, space: ParamSpace, theta: np.ndarray, shown: Sequence[Shown]
) -> float:
    """Mean squared difference between the actions shown and those the person imagines with
    parameters θ (its own calm controller fed the shown states)."""
    if not shown:
        return 0.0
    imagined = imagine(task, watching(motor, space.choices(theta)), [s.states for s in shown])
    total, count = 0.0, 0
    for s, a in zip(shown, imagined, strict=True):
        err = action_error([a], [s.actions], [s.span], s.weights)
        n = len(np.asarray(s.actions)[s.span]) * np.asarray(s.actions).shape[1]
        total, count = total + err * n, count + n
    return total / max(count, 1)


def fit_theta(
    task: Any,
    motor: Style,
    space: ParamSpace,
    theta: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray],
    shown: Sequence[Shown],
    first_step: float = FIRST_STEP,
) -> tuple[np.ndarray, float, float]:
    """The θ within ``bounds`` that best predicts the shown actions, searched from ``theta``
    (``first_step``: the search's first step, a fraction of each reachable range).

    Returns:
      ``(θ found, error at the start, error at θ found)``.
    """

    def f(t: np.ndarray) -> float:
        return imagined_error(task, motor, space, t, shown)

    best, after, _ = compass_search(f, theta, bounds[0], bounds[1], first_step=first_step)
    return best, f(theta), after
