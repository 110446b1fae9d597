"""A person's continuous parameters θ per task: names, bounds, the operator choices they drive,
and the per-task prior a person's starting θ is drawn from.

A simulated person runs the task's scripted state machine (the phases of the task are task
knowledge) with its *own* parameter vector θ. Each task declares a :class:`ParamSpace`: named
coordinates with bounds, a map θ → the operator's choices (:meth:`ParamSpace.choices`), the
region of θ a style's choices pin down (:meth:`ParamSpace.regions`), a **prior** over θ and the
θ of its **compatible** person. Discrete operator choices (route, approach, carry order) are
continuous coordinates thresholded at a fixed value, so an optimiser can move across them; a
yaw offset or a via-point offset between the scripted values is a style no scripted operator
has (a blend).

**Start.** A person's starting θ (:meth:`ParamSpace.start`) takes, per coordinate, a draw from
the prior restricted to what its starting style's choices say about that coordinate; a
coordinate the style says nothing about is a plain prior draw — never the operator class's
default, which is the base operator's value. The priors are the study designer's, stated
here per task; none is centred on the base operator's θ, and none reaches the region of the
study's contrast-set style (``docs/people.md`` lists both and the measured distances).

Nothing here knows the task's list of styles or reads the base operator's parameters: a space
maps whatever choices it is given.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError

Choices = Mapping[str, Any]
Interval = tuple[float, float]
Region = tuple[Interval, ...]
"""A union of closed intervals of one coordinate (a single value: ``((v, v),)``)."""
BELOW = 1e-6
"""How far below a threshold a "below" region ends (thresholds count as above)."""


def point(value: float) -> Region:
    """The region of one value."""
    return ((float(value), float(value)),)


def draw(region: Region, within: Region, rng: np.random.Generator) -> float:
    """A uniform draw from ``region ∩ within`` (by length; among the single values it holds
    when it has no length), or from ``region`` alone when they do not meet."""
    meet = [(max(a, c), min(b, d)) for a, b in region for c, d in within if max(a, c) <= min(b, d)]
    for pool in (meet, list(region)):
        spans = [(a, b) for a, b in pool if b > a]
        if spans:
            lengths = np.array([b - a for a, b in spans])
            a, b = spans[int(rng.choice(len(spans), p=lengths / lengths.sum()))]
            return float(rng.uniform(a, b))
        if pool:
            return float(pool[int(rng.integers(len(pool)))][0])
    raise ElicitError("a person's parameter region is empty")


@dataclasses.dataclass(frozen=True)
class ParamSpace:
    """The continuous parameters a person of one task adjusts.

    Attributes:
      names: coordinate names, in order.
      low, high: bounds per coordinate.
      to_choices: θ (array) -> the operator's choices.
      from_choices: the operator's choices -> ``{name: region}`` for the coordinates they
        pin down (a value, or a side of a threshold); the others are absent.
      prior: per coordinate, the region a person's starting value is drawn from (uniform).
      compatible: the compatible (``same-style``) person's starting θ, stated.
      angular: coordinates that are angles (their differences wrap; see :meth:`distance`).
    """

    names: tuple[str, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    to_choices: Callable[[np.ndarray], dict[str, Any]]
    from_choices: Callable[[Choices], dict[str, Region]]
    prior: tuple[Region, ...]
    compatible: tuple[float, ...]
    angular: tuple[str, ...] = ()

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

    def regions(self, choices: Choices | tuple[tuple[str, Any], ...]) -> dict[str, Region]:
        """``{name: region}`` of the coordinates a style's choices pin down."""
        return self.from_choices(dict(choices))

    def start(
        self, choices: Choices | tuple[tuple[str, Any], ...], rng: np.random.Generator
    ) -> np.ndarray:
        """A starting θ for a style's choices: per coordinate, the prior restricted to the
        style's region for it (the plain prior where the style says nothing)."""
        pinned = self.regions(choices)
        drawn = [
            draw(pinned.get(name, ((lo, hi),)), prior, rng)
            for name, lo, hi, prior in zip(self.names, self.low, self.high, self.prior, strict=True)
        ]
        return self.clip(np.array(drawn))

    def prior_draw(self, rng: np.random.Generator) -> np.ndarray:
        """θ drawn from the prior alone."""
        return self.start({}, rng)

    def theta(self, choices: Choices | tuple[tuple[str, Any], ...]) -> np.ndarray:
        """θ of a style whose choices pin down every coordinate (a single value as itself; a
        side of a threshold as the bound on that side, or its middle if it has none).

        Raises:
          ElicitError: the choices leave a coordinate open.
        """
        pinned = self.regions(choices)
        missing = [n for n in self.names if n not in pinned]
        if missing:
            raise ElicitError(f"the choices leave {', '.join(missing)} open")
        out = []
        for name, lo, hi in zip(self.names, self.low, self.high, strict=True):
            (a, b), *_ = pinned[name]
            out.append(a if a == b or a <= lo else b if b >= hi else (a + b) / 2)
        return self.clip(np.array(out))

    def differences(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Per coordinate, ``|a - b|`` as a fraction of the largest difference possible (the
        range; half a turn for an angle, whose difference wraps)."""
        diff = np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))
        scale = self.width.astype(np.float64).copy()
        for i, name in enumerate(self.names):
            if name in self.angular:
                diff[i] = abs((diff[i] + np.pi) % (2 * np.pi) - np.pi)
                scale[i] = np.pi
        return diff / scale

    def distance(self, a: np.ndarray, b: np.ndarray) -> float:
        """Mean of :meth:`differences`: 0 the same θ, 1 as far apart as the space allows."""
        return float(np.mean(self.differences(a, b)))

    def within(self, theta: np.ndarray, region: Mapping[str, Region], tol: float) -> bool:
        """θ lies in ``region`` on every coordinate it names: inside a side of a threshold, or
        within ``tol`` (of the largest difference, :meth:`differences`) of a single value."""
        theta = np.asarray(theta, np.float64)
        for name, parts in region.items():
            i = self.names.index(name)
            hit = False
            for a, b in parts:
                if a == b:
                    value = theta.copy()
                    value[i] = a
                    hit |= bool(self.differences(theta, value)[i] <= tol)
                else:
                    hit |= bool(a <= theta[i] <= b)
            if not hit:
                return False
        return True

    def named(self, theta: np.ndarray) -> dict[str, float]:
        """``{name: value}`` of θ (for records)."""
        return {n: round(float(v), 6) for n, v in zip(self.names, theta, strict=True)}


def _pause(choices: Choices, phases: tuple[int, ...]) -> dict[str, Region]:
    """The pause a style's ``pause_at`` choice pins down (none if it does not set it)."""
    if "pause_at" not in choices:
        return {}
    at = tuple(choices["pause_at"])
    return {"pause": point(choices.get("pause_steps", 0) if any(p in at for p in phases) else 0)}


def _with_pause(out: dict[str, Any], steps: float, phases: tuple[int, ...]) -> dict[str, Any]:
    n = round(steps)
    if n >= 1:
        out["pause_at"], out["pause_steps"] = phases, n
    return out


def _side(value: Any, above: str, threshold: float = 0.5, high: float = 1.0) -> Region:
    """The region of a two-way choice thresholded at ``threshold``."""
    return ((threshold, high),) if value == above else ((0.0, threshold - BELOW),)


# --- reach-pillar: lateral via-point offset (signed, + = left), over the top, pause at start --
_REACH_PAUSE = (0,)
_OVER = 0.5
_LATERAL = 0.16


def _reach_choices(t: np.ndarray) -> dict[str, Any]:
    lateral, over, pause = (float(v) for v in t)
    if over >= _OVER:
        out: dict[str, Any] = {"route": "over", "clearance": max(abs(lateral), 0.02)}
    else:
        out = {"route": "left" if lateral >= 0 else "right", "clearance": abs(lateral)}
    return _with_pause(out, pause, _REACH_PAUSE)


def _reach_regions(c: Choices) -> dict[str, Region]:
    out = _pause(c, _REACH_PAUSE)
    route, clear = c.get("route"), c.get("clearance")
    if route is not None:
        out["over"] = _side(route, "over", _OVER)
    if route == "left":
        out["lateral"] = point(clear) if clear is not None else ((0.0, _LATERAL),)
    elif route == "right":
        out["lateral"] = point(-clear) if clear is not None else ((-_LATERAL, 0.0),)
    elif clear is not None:  # either side (or over the top) at this clearance
        out["lateral"] = (*point(-clear), *point(clear))
    return out


REACH_PILLAR = ParamSpace(
    names=("lateral", "over", "pause"),
    low=(-_LATERAL, 0.0, 0.0),
    high=(_LATERAL, 1.0, 60.0),
    to_choices=_reach_choices,
    from_choices=_reach_regions,
    # an arc wider than 10 cm on either side; never over the top (the contrast set's way); a
    # pause at the start of up to half the 60 allowed
    prior=(((-_LATERAL, -0.10), (0.10, _LATERAL)), ((0.0, 0.45),), ((0.0, 30.0),)),
    compatible=(0.12, 0.2, 0.0),
)


# --- the handle tasks (the nuts, the hammer): wrist yaw, grasp point, a choice of the task's
# own, carry order, pause ------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class _HandleTask:
    """θ → choices and choices → regions of a task whose person grasps a handle: θ is (wrist
    yaw offset, grasp offset along the handle, the task's own choice, carry order, pause), the
    first two choices as they are, the carry order a two-way choice thresholded at 0.5.
    Each task states only what differs.

    Attributes:
      pause_phases: the phases a pause holds still before.
      own: the task's own coordinate's value -> the choices it drives.
      own_region: a style's choices -> ``{name: region}`` of the task's own coordinate (empty
        when the choices do not set it).
      carry: the carry order's choice below 0.5 and at or above it.
    """

    pause_phases: tuple[int, ...]
    own: Callable[[float], dict[str, Any]]
    own_region: Callable[[Choices], dict[str, Region]]
    carry: tuple[str, str]

    def choices(self, t: np.ndarray) -> dict[str, Any]:
        """The operator's choices for θ (already clipped)."""
        yaw, grasp, own, carry, pause = (float(v) for v in t)
        out: dict[str, Any] = {"yaw_offset": yaw, "grasp_offset": grasp, **self.own(own)}
        out["carry"] = self.carry[1] if carry >= 0.5 else self.carry[0]
        return _with_pause(out, pause, self.pause_phases)

    def regions(self, c: Choices) -> dict[str, Region]:
        """``{name: region}`` of the coordinates the choices ``c`` pin down."""
        out = _pause(c, self.pause_phases)
        for name in ("yaw_offset", "grasp_offset"):
            if name in c:
                out[name] = point(c[name])
        out |= self.own_region(c)
        if "carry" in c:
            out["carry"] = _side(c["carry"], self.carry[1])
        return out


_YAW_PRIOR: Region = ((0.1, 0.4), (np.pi - 0.4, np.pi - 0.1))
"""A wrist turned 0.1-0.4 rad (one way) off either way of holding the handle: as the base
does, or half a turn round."""


# --- square-nut / round-nut: approach from the tip or from above, carry diagonally ----------
def _approach(v: float) -> dict[str, Any]:
    return {"approach": "tip" if v >= 0.5 else "above"}


def _approach_region(c: Choices) -> dict[str, Region]:
    return {"approach": _side(c["approach"], "tip")} if "approach" in c else {}


_NUT = _HandleTask(
    pause_phases=(0, 1, 5),  # before the first move, the descent and the lowering onto the peg
    own=_approach,
    own_region=_approach_region,
    carry=("lift-first", "diagonal"),
)

NUT = ParamSpace(
    names=("yaw_offset", "grasp_offset", "approach", "carry", "pause"),
    low=(-np.pi, 0.035, 0.0, 0.0, 0.0),
    high=(np.pi, 0.075, 1.0, 1.0, 80.0),
    to_choices=_NUT.choices,
    from_choices=_NUT.regions,
    # the grasp 5-17 mm further out along the handle; either approach and carry; a pause of up
    # to 40 steps (the contrast set's style holds still 80)
    prior=(
        _YAW_PRIOR,
        ((0.063, 0.075),),
        ((0.0, 1.0),),
        ((0.0, 1.0),),
        ((0.0, 40.0),),
    ),
    compatible=(0.05, 0.062, 0.2, 0.2, 0.0),
    angular=("yaw_offset",),
)

# --- hammer-drawer: the head laid towards +y, -y or the nearest way (3-way), carry low -----
_THIRD = 1 / 3


def _place(v: float) -> dict[str, Any]:
    if v > _THIRD:
        return {"place_yaw": np.pi / 2}
    if v < -_THIRD:
        return {"place_yaw": -np.pi / 2}
    return {"place_yaw": "nearest"}


def _place_region(c: Choices) -> dict[str, Region]:
    if "place_yaw" not in c:
        return {}
    place = c["place_yaw"]
    if isinstance(place, str):
        return {"place": ((-_THIRD, _THIRD),)}
    return {"place": ((_THIRD + BELOW, 1.0),) if place > 0 else ((-1.0, -_THIRD - BELOW),)}


_HAMMER = _HandleTask(
    pause_phases=(4,),  # above the opened drawer, before going to the hammer
    own=_place,
    own_region=_place_region,
    carry=("lift-first", "low-first"),
)

HAMMER_DRAWER = ParamSpace(
    names=("yaw_offset", "grasp_offset", "place", "carry", "pause"),
    low=(-np.pi, -0.04, -1.0, 0.0, 0.0),
    high=(np.pi, 0.02, 1.0, 1.0, 40.0),
    to_choices=_HAMMER.choices,
    from_choices=_HAMMER.regions,
    # the grasp 10-40 mm further along the handle; the head laid towards +y or the nearest
    # way, never towards -y (the contrast set's way); lifted first (carrying low first, with a
    # flip and a pause, runs out of the 175 steps: measured, docs/people.md); a pause up to 30
    prior=(
        _YAW_PRIOR,
        ((-0.035, -0.005),),
        ((-_THIRD, 1.0),),
        ((0.0, 0.5 - BELOW),),
        ((0.0, 30.0),),
    ),
    compatible=(0.05, 0.0, 0.8, 0.2, 0.0),
    angular=("yaw_offset",),
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


__all__ = ["ParamSpace", "Region", "draw", "point", "space_of"]
