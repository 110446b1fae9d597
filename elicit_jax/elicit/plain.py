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
  sentence above applies), the gripper
  closed where the base's is open or the reverse, and holding still where the base moves.

:func:`plain_words` returns the sentences, most specific first.
"""

from __future__ import annotations

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
AXES = (
    ("forward", "back", "W", "S"),
    ("left", "right", "A", "D"),
    ("higher", "lower", "R", "F"),
)


def _sim_layout(fields: Sequence[Any]) -> bool:
    """The states follow the simulated tasks' layout (gripper pose, fingers, object)."""
    return [f.name for f in fields] == list(LAYOUT)


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


def plain_words(
    task: str,
    fields: Sequence[Any],
    op_window: np.ndarray,
    base_segment: np.ndarray,
    op_episode: np.ndarray,
    base_episode: np.ndarray,
    motion: str = "",
) -> tuple[str, ...]:
    """The window's differences from its base segment in plain words, most specific first.

    Args:
      task: the task's name.
      fields: the states' ``ObsField``s (other layouts get the motion sentence only).
      op_window: (W, O) the operator's states in the window.
      base_segment: (W, O) the base segment's states, aligned to the window's length.
      op_episode: (T, O) the operator's whole episode (the route around an obstacle).
      base_episode: (T', O) the whole retrieved base demonstration.
      motion: ``still``, ``moving`` or ``""`` (:func:`elicit_jax.elicit.explain.motion`).

    Returns:
      Sentences (possibly none).
    """
    out: list[str] = []
    op, base = np.asarray(op_window, np.float64), np.asarray(base_segment, np.float64)
    if _sim_layout(fields) and op.shape[1] >= 23:
        if task == "reach-pillar":
            out.append(pillar_sentence(op, base, op_episode, base_episode))
        elif task in ("square-nut", "round-nut"):
            from elicit_jax.sim.tasks.square_nut import HANDLE_FROM, HANDLE_TO

            out += nut_sentences(op, base, (HANDLE_FROM, HANDLE_TO))
        if not any(out):  # the route or the grip says it better than an offset
            out.append(offset_sentence(op, base))
        out.append(gripper_sentence(op, base))
    if motion == "still":
        out.append("you hold still where the base moves")
    elif motion == "moving":
        out.append("you move where the base holds still")
    return tuple(s for s in out if s)
