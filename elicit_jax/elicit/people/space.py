"""A person's continuous parameters θ per task: names, bounds, and the operator choices they
drive.

A simulated person runs the task's scripted state machine (the phases of the task are task
knowledge) with its *own* parameter vector θ. Each task declares a :class:`ParamSpace`: named
coordinates with bounds, a map θ → the operator's choices (:meth:`ParamSpace.choices`), and
the inverse for a person's starting style (:meth:`ParamSpace.theta`). Discrete operator choices
(route, approach, carry order) are continuous coordinates thresholded at a fixed value, so an
optimiser can move across them; a yaw offset or a via-point offset between the scripted
values is a style no scripted operator has (a blend).

Nothing here knows the task's list of styles or the base operator's parameters: a space maps
whatever choices it is given.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError

Choices = Mapping[str, Any]


@dataclasses.dataclass(frozen=True)
class ParamSpace:
    """The continuous parameters a person of one task adjusts.

    Attributes:
      names: coordinate names, in order.
      low, high: bounds per coordinate.
      to_choices: θ (array) -> the operator's choices.
      from_choices: the operator's choices -> θ (array).
    """

    names: tuple[str, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    to_choices: Callable[[np.ndarray], dict[str, Any]]
    from_choices: Callable[[Choices], np.ndarray]

    @property
    def width(self) -> np.ndarray:
        """``high - low`` per coordinate."""
        return np.asarray(self.high) - np.asarray(self.low)

    def clip(self, theta: np.ndarray, low: np.ndarray | None = None,
             high: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
        """θ clipped to the space (or to the narrower ``low``/``high`` given)."""
        lo = np.asarray(self.low) if low is None else low
        hi = np.asarray(self.high) if high is None else high
        return np.clip(np.asarray(theta, np.float64), lo, hi)

    def choices(self, theta: np.ndarray) -> dict[str, Any]:
        """The operator's choices for θ."""
        return self.to_choices(self.clip(theta))

    def theta(self, choices: Choices | tuple[tuple[str, Any], ...]) -> np.ndarray:
        """θ of a style's choices (a mapping or a style's ``(key, value)`` pairs)."""
        return self.clip(self.from_choices(dict(choices)))

    def named(self, theta: np.ndarray) -> dict[str, float]:
        """``{name: value}`` of θ (for records)."""
        return {n: round(float(v), 6) for n, v in zip(self.names, theta, strict=True)}


def _pause(choices: Choices, phases: tuple[int, ...]) -> float:
    at = tuple(choices.get("pause_at", ()))
    return float(choices.get("pause_steps", 0)) if any(p in at for p in phases) else 0.0


def _with_pause(out: dict[str, Any], steps: float, phases: tuple[int, ...]) -> dict[str, Any]:
    n = round(steps)
    if n >= 1:
        out["pause_at"], out["pause_steps"] = phases, n
    return out


# --- reach-pillar: lateral via-point offset (signed, + = left), over the top, pause at start --
_REACH_PAUSE = (0,)
_OVER = 0.5


def _reach_choices(t: np.ndarray) -> dict[str, Any]:
    lateral, over, pause = (float(v) for v in t)
    if over >= _OVER:
        out: dict[str, Any] = {"route": "over", "clearance": max(abs(lateral), 0.02)}
    else:
        out = {"route": "left" if lateral >= 0 else "right", "clearance": abs(lateral)}
    return _with_pause(out, pause, _REACH_PAUSE)


def _reach_theta(c: Choices) -> np.ndarray:
    clear = float(c.get("clearance", 0.09))
    route = c.get("route", "left")
    lateral = -clear if route == "right" else clear
    return np.array([lateral, 1.0 if route == "over" else 0.0, _pause(c, _REACH_PAUSE)])


REACH_PILLAR = ParamSpace(
    names=("lateral", "over", "pause"),
    low=(-0.16, 0.0, 0.0),
    high=(0.16, 1.0, 60.0),
    to_choices=_reach_choices,
    from_choices=_reach_theta,
)

# --- square-nut / round-nut: wrist yaw, grasp point, approach and carry blends, pauses --------
_NUT_PAUSE = (0, 1, 5)  # before the first move, the descent and the lowering onto the peg


def _nut_choices(t: np.ndarray) -> dict[str, Any]:
    yaw, grasp, approach, carry, pause = (float(v) for v in t)
    out: dict[str, Any] = {"yaw_offset": yaw, "grasp_offset": grasp}
    out["approach"] = "tip" if approach >= 0.5 else "above"
    out["carry"] = "diagonal" if carry >= 0.5 else "lift-first"
    return _with_pause(out, pause, _NUT_PAUSE)


def _nut_theta(c: Choices) -> np.ndarray:
    return np.array(
        [
            float(c.get("yaw_offset", 0.0)),
            float(c.get("grasp_offset", 0.058)),
            1.0 if c.get("approach", "above") == "tip" else 0.0,
            1.0 if c.get("carry", "lift-first") == "diagonal" else 0.0,
            _pause(c, _NUT_PAUSE),
        ]
    )


NUT = ParamSpace(
    names=("yaw_offset", "grasp_offset", "approach", "carry", "pause"),
    low=(-np.pi, 0.035, 0.0, 0.0, 0.0),
    high=(np.pi, 0.075, 1.0, 1.0, 80.0),
    to_choices=_nut_choices,
    from_choices=_nut_theta,
)

# --- hammer-drawer: wrist yaw, grasp point, placing yaw (3-way), carry order, pause ----------
_HAMMER_PAUSE = (4,)  # above the opened drawer, before going to the hammer


def _hammer_choices(t: np.ndarray) -> dict[str, Any]:
    yaw, grasp, place, carry, pause = (float(v) for v in t)
    out: dict[str, Any] = {"yaw_offset": yaw, "grasp_offset": grasp}
    if place > 1 / 3:
        out["place_yaw"] = np.pi / 2
    elif place < -1 / 3:
        out["place_yaw"] = -np.pi / 2
    else:
        out["place_yaw"] = "nearest"
    out["carry"] = "low-first" if carry >= 0.5 else "lift-first"
    return _with_pause(out, pause, _HAMMER_PAUSE)


def _hammer_theta(c: Choices) -> np.ndarray:
    place = c.get("place_yaw", np.pi / 2)
    p = 0.0 if isinstance(place, str) else float(np.sign(place))
    return np.array(
        [
            float(c.get("yaw_offset", 0.0)),
            float(c.get("grasp_offset", 0.005)),
            p,
            1.0 if c.get("carry", "lift-first") == "low-first" else 0.0,
            _pause(c, _HAMMER_PAUSE),
        ]
    )


HAMMER_DRAWER = ParamSpace(
    names=("yaw_offset", "grasp_offset", "place", "carry", "pause"),
    low=(-np.pi, -0.04, -1.0, 0.0, 0.0),
    high=(np.pi, 0.02, 1.0, 1.0, 40.0),
    to_choices=_hammer_choices,
    from_choices=_hammer_theta,
)

SPACES: dict[str, ParamSpace] = {
    "reach-pillar": REACH_PILLAR,
    "square-nut": NUT,
    "round-nut": NUT,
    "hammer-drawer": HAMMER_DRAWER,
}


def space_of(task_name: str) -> ParamSpace:
    """The parameter space of a task's people.

    Raises:
      ElicitError: no simulated people for this task.
    """
    if task_name not in SPACES:
        raise ElicitError(
            f"no simulated people for task '{task_name}' (known: {', '.join(SPACES)})"
        )
    return SPACES[task_name]
