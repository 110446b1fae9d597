"""Feedback in plain words: what an operator did differently from the base, from the geometry.

The numbers of :mod:`elicit_jax.elicit.explain` (field differences in units of the data's
spread) mean little to a lay operator. This module reads the states of a flagged window and
of the base segment retrieved for it — never the operator's style or anything but states —
and says the difference the way a person would act on it, naming the keys that fix it:

* **reach-pillar**: which side of the pillar each passed — the step where the gripper
  crosses the pillar's plane (``x`` = the pillar's), over it when above its top, else left
  (``+y``) or right; within the window where both are beside the pillar, else over the
  whole episodes: ``you went right of the pillar; the base goes left of it``;
* **square-nut, round-nut**: how the wrist is turned against the nut (the nut's yaw in the
  gripper's frame; half a turn apart: the handle held the other way round), and where along
  the handle the gripper closes (the gripper's position in the nut's frame, the handle
  running along the nut's ``+x``);
* **every task with the gripper's position** (``robot0_eef_pos``): where the gripper is
  against the base's (forward/back, left/right, up/down, in cm, with the keys; when no
  sentence above applies), the gripper closed where the base's is open or the reverse;
* **how the gripper moves** (:func:`gripper_motion`, in the task's own terms: metres per
  step of the gripper along each axis, its turn and its fingers — never a normalised blend
  of every state dimension, which reads fast motion along one axis as standing still):
  holding still (paused in most steps) where the base moves, moving where the base holds
  still, moving another way (``you move right (D) where the base moves forward (W)``), and
  moving much faster or slower than the base.

:func:`plain_words` returns the sentences, most specific first.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

EEF, QUAT, FINGERS = slice(0, 3), slice(3, 7), slice(7, 9)
OBJ_POS, OBJ_QUAT, REL_QUAT = slice(9, 12), slice(12, 16), slice(19, 23)
LAYOUT = ("robot0_eef_pos", "robot0_eef_quat", "robot0_gripper_qpos", "object")
OFFSET_M = 0.02
"""A position difference below 2 cm is not worth mentioning."""
BESIDE_PILLAR_M = 0.06
CLOSED_Q = 0.02
"""Fingers (each 0.04 open) below this are closed."""
TURNED_RAD = np.pi / 2
PAUSE_M = 0.001
"""The gripper moves under 1 mm in a step (and neither turns nor opens): a paused step."""
TURN_RAD = 0.01
MOVING_M = 0.0015
"""A gripper moving at least 1.5 mm a step on average is moving (a held key: 2.4 mm with
Shift, 8 mm without)."""
NET_M = 0.01
"""A window's net displacement under 1 cm has no direction worth naming."""
SPEED_RATIO = 2.0
AXES = (
    ("forward", "back", "W", "S"),
    ("left", "right", "A", "D"),
    ("higher", "lower", "R", "F"),
)


def sim_layout(fields: Sequence[Any], obs_dim: int = 23) -> bool:
    """The states follow the simulated tasks' layout (gripper pose, fingers, object)."""
    return [f.name for f in fields] == list(LAYOUT) and obs_dim >= 23


def _yaw(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _wrap(a: np.ndarray | float) -> Any:
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def pillar_side(obs: np.ndarray, pillar: tuple[float, float], height: float) -> str:
    """Where a reach-pillar path passes the pillar: ``left``, ``right``, ``over`` or ``""``
    (it never reaches the pillar's plane).

    Args:
      obs: (T, O) states; the gripper's position first.
      pillar: the pillar's (x, y).
      height: the pillar's height.
    """
    p = np.asarray(obs, np.float64)[:, EEF]
    past = np.flatnonzero(p[:, 0] >= pillar[0])
    if not len(past):
        return ""
    _, y, z = p[past[0]]
    return "over" if z > height else "left" if y > pillar[1] else "right"


def _beside(obs: np.ndarray, pillar: tuple[float, float], height: float) -> str:
    """The side most steps of ``obs`` beside the pillar are on (``""``: none beside it)."""
    p = np.asarray(obs, np.float64)[:, EEF]
    near = np.abs(p[:, 0] - pillar[0]) < BESIDE_PILLAR_M
    if not near.any():
        return ""
    sides = np.where(p[near, 2] > height, "over", np.where(p[near, 1] > pillar[1], "left", "right"))
    values, counts = np.unique(sides, return_counts=True)
    return str(values[np.argmax(counts)])


def pillar_sentence(
    op_window: np.ndarray,
    base_segment: np.ndarray,
    op_episode: np.ndarray,
    base_episode: np.ndarray,
) -> str:
    """reach-pillar: the side of the pillar, where the operator's differs from the base's."""
    from elicit_jax.sim.tasks.reach_pillar import PILLAR_HEIGHT, PILLAR_XY

    mine, theirs = (
        _beside(op_window, PILLAR_XY, PILLAR_HEIGHT),
        _beside(base_segment, PILLAR_XY, PILLAR_HEIGHT),
    )
    if not (mine and theirs):
        mine = pillar_side(op_episode, PILLAR_XY, PILLAR_HEIGHT)
        theirs = pillar_side(base_episode, PILLAR_XY, PILLAR_HEIGHT)
    if not mine or not theirs or mine == theirs:
        return ""
    you = "you went over the pillar" if mine == "over" else f"you went {mine} of the pillar"
    base = "the base goes over it" if theirs == "over" else f"the base goes {theirs} of it"
    return f"{you}; {base}"


def nut_sentences(op: np.ndarray, base: np.ndarray, handle: tuple[float, float]) -> list[str]:
    """Nut tasks: the wrist's turn against the nut, and where along the handle it closes."""
    out = []
    rel = _wrap(np.mean(_wrap(_yaw(op[:, REL_QUAT]) - _yaw(base[:, REL_QUAT]))))
    if abs(rel) > TURNED_RAD:
        deg = int(round(np.degrees(abs(rel)) / 10) * 10)
        out.append(
            f"your wrist is turned about {deg}° from the base's against the nut: the base holds "
            "the handle the other way round (turn with Q / E)"
        )
    closed_op = op[:, FINGERS].mean(axis=1) < CLOSED_Q
    closed_base = base[:, FINGERS].mean(axis=1) < CLOSED_Q
    both = closed_op & closed_base
    if both.any():
        along = [_along_handle(x[both]) for x in (op, base)]
        if along[0] < handle[0] - 0.005 and along[1] >= handle[0] - 0.005:
            out.append("you hold the nut by its ring; the base holds it by the handle")
        elif abs(along[0] - along[1]) > OFFSET_M:
            where = "nearer the handle's end" if along[0] > along[1] else "nearer the ring"
            out.append(
                f"you hold the handle {100 * abs(along[0] - along[1]):.0f} cm {where} than the base"
            )
    return out


def _along_handle(x: np.ndarray) -> float:
    """Mean position of the gripper along the nut's handle axis (the nut's +x), in m."""
    yaw = _yaw(x[:, OBJ_QUAT])
    d = x[:, EEF] - x[:, OBJ_POS]
    return float(np.mean(d[:, 0] * np.cos(yaw) + d[:, 1] * np.sin(yaw)))


def offset_sentence(op: np.ndarray, base: np.ndarray) -> str:
    """Where the operator's gripper is against the base's, on average over the window."""
    d = op[:, EEF].mean(axis=0) - base[:, EEF].mean(axis=0)
    parts, keys = [], []
    for axis, (v, (pos, neg, kpos, kneg)) in enumerate(zip(d, AXES, strict=True)):
        if abs(v) >= OFFSET_M:
            word = pos if v > 0 else neg
            parts.append(f"{100 * abs(v):.0f} cm {word if axis == 2 else 'further ' + word}")
            keys.append(kneg if v > 0 else kpos)
    if not parts:
        return ""
    return f"your gripper is {' and '.join(parts)} than the base's here (keys {', '.join(keys)})"


def gripper_sentence(op: np.ndarray, base: np.ndarray) -> str:
    """Open where the base's is closed, or the reverse, over most of the window."""
    closed_op = float(np.mean(op[:, FINGERS].mean(axis=1) < CLOSED_Q))
    closed_base = float(np.mean(base[:, FINGERS].mean(axis=1) < CLOSED_Q))
    if closed_op > 0.5 >= closed_base:
        return "you close the gripper where the base keeps it open (G)"
    if closed_base > 0.5 >= closed_op:
        return "you keep the gripper open where the base has closed it (G)"
    return ""


@dataclasses.dataclass(frozen=True)
class GripperMotion:
    """How the gripper moves over a window, in the task's own units.

    Attributes:
      speed: mean distance the gripper moves per step (m).
      paused: fraction of steps it is still (under :data:`PAUSE_M`, not turning, the
        fingers not moving).
      net: (3,) its displacement over the window (m; x forward, y left, z up).
    """

    speed: float
    paused: float
    net: tuple[float, float, float]

    @property
    def still(self) -> bool:
        """Paused in at least half of its steps."""
        return self.paused >= 0.5

    @property
    def moving(self) -> bool:
        return not self.still and self.speed >= MOVING_M


def gripper_motion(states: np.ndarray) -> GripperMotion:
    """The gripper's motion over ``states (T, O)`` of the simulated layout (T < 2: still)."""
    x = np.asarray(states, np.float64)
    if len(x) < 2:
        return GripperMotion(0.0, 1.0, (0.0, 0.0, 0.0))
    step = np.linalg.norm(np.diff(x[:, EEF], axis=0), axis=1)
    turn = np.abs(_wrap(np.diff(_yaw(x[:, QUAT]))))
    fingers = np.abs(np.diff(x[:, FINGERS].mean(axis=1)))
    still = (step < PAUSE_M) & (turn < TURN_RAD) & (fingers < PAUSE_M / 2)
    net = x[-1, EEF] - x[0, EEF]
    return GripperMotion(float(step.mean()), float(still.mean()), tuple(float(v) for v in net))


def motion_kind(op: GripperMotion, base: GripperMotion) -> str:
    """``still`` (the operator holds still where the base moves), ``moving`` (the reverse)
    or ``""``."""
    if op.still and base.moving:
        return "still"
    if base.still and op.moving:
        return "moving"
    return ""


def _direction(net: Sequence[float]) -> str:
    """The main directions of a displacement, with their keys: ``forward and right (W, D)``."""
    v = np.asarray(net, np.float64)
    big = np.abs(v).max()
    words, keys = [], []
    for axis in np.argsort(-np.abs(v)):
        if abs(v[axis]) >= 0.5 * big:
            pos, neg, kpos, kneg = AXES[axis]
            if axis == 2:
                words.append("up" if v[axis] > 0 else "down")
            else:
                words.append(pos if v[axis] > 0 else neg)
            keys.append(kpos if v[axis] > 0 else kneg)
    return f"{' and '.join(words)} ({', '.join(keys)})"


def motion_sentences(op: np.ndarray, base: np.ndarray) -> list[str]:
    """How the operator's gripper moves against the base's over the window: holding still,
    moving, another direction, another speed (the base segment at its own steps)."""
    if len(op) < 2 or len(base) < 2:  # a single step has no motion to speak of
        return []
    mine, theirs = gripper_motion(op), gripper_motion(base)
    mm = (1000 * mine.speed, 1000 * theirs.speed)
    kind = motion_kind(mine, theirs)
    n = len(op) - 1
    if kind == "still":
        return [
            f"you hold still where the base moves (your gripper still in "
            f"{round(mine.paused * n)} of {n} steps; the base's moves {mm[1]:.0f} mm a step)"
        ]
    if kind == "moving":
        return [
            f"you move where the base holds still (your gripper {mm[0]:.0f} mm a step; the "
            "base's pauses here)"
        ]
    if not (mine.moving and theirs.moving):
        return []
    a, b = np.asarray(mine.net), np.asarray(theirs.net)
    if min(np.linalg.norm(a), np.linalg.norm(b)) >= NET_M:
        cos = float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))
        if cos < 0.5:  # more than 60° apart
            return [f"you move {_direction(a)} where the base moves {_direction(b)}"]
    ratio = mine.speed / theirs.speed
    if ratio >= SPEED_RATIO:
        return [
            f"you move about {ratio:.0f}× as fast as the base here ({mm[0]:.0f} vs "
            f"{mm[1]:.0f} mm a step; Shift slows you down)"
        ]
    if ratio <= 1 / SPEED_RATIO:
        return [
            f"you move at about {100 * ratio:.0f}% of the base's speed here ({mm[0]:.0f} vs "
            f"{mm[1]:.0f} mm a step)"
        ]
    return []


def plain_words(
    task: str,
    fields: Sequence[Any],
    op_window: np.ndarray,
    base_segment: np.ndarray,
    op_episode: np.ndarray,
    base_episode: np.ndarray,
    motion: str = "",
    base_steps: np.ndarray | None = None,
) -> tuple[str, ...]:
    """The window's differences from its base segment in plain words, most specific first.

    Args:
      task: the task's name.
      fields: the states' ``ObsField``s (other layouts get the motion sentence only).
      op_window: (W, O) the operator's states in the window.
      base_segment: (W, O) the base segment's states, aligned to the window's length.
      op_episode: (T, O) the operator's whole episode (the route around an obstacle).
      base_episode: (T', O) the whole retrieved base demonstration.
      motion: ``still``, ``moving`` or ``""`` (:func:`elicit_jax.elicit.explain.motion`),
        used for other layouts only: the simulated layout's motion is read from the gripper
        (:func:`motion_sentences`).
      base_steps: (S, O) the base segment at its own steps (its speed), default
        ``base_segment``.

    Returns:
      Sentences (possibly none).
    """
    out: list[str] = []
    op, base = np.asarray(op_window, np.float64), np.asarray(base_segment, np.float64)
    if sim_layout(fields, op.shape[1]):
        if task == "reach-pillar":
            out.append(pillar_sentence(op, base, op_episode, base_episode))
        elif task in ("square-nut", "round-nut"):
            from elicit_jax.sim.tasks.square_nut import HANDLE_FROM, HANDLE_TO

            out += nut_sentences(op, base, (HANDLE_FROM, HANDLE_TO))
        if not any(out):  # the route or the grip says it better than an offset
            out.append(offset_sentence(op, base))
        out.append(gripper_sentence(op, base))
        steps = base if base_steps is None else np.asarray(base_steps, np.float64)
        out += motion_sentences(op, steps)
    elif motion == "still":
        out.append("you hold still where the base moves")
    elif motion == "moving":
        out.append("you move where the base holds still")
    return tuple(s for s in out if s)
