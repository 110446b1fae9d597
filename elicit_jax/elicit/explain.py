"""Feedback beyond the paper: what differs in each flagged window, per field, in one line.

The paper shows an operator the windows of a rejected demonstration with the highest mean
incompatibility and the base demonstration retrieved for each
(:func:`elicit_jax.compat.feedback.episode_feedback`). This module says *what* differs. For
each window, the retrieved base segment is aligned to the window's length (nearest index on
an even grid) and compared:

* **observation fields** (the demos' ``obs_fields``): per field, the mean over the window of
  the difference between the operator's and the base's states — the rotation angle for a
  4-value quaternion field (a name containing ``quat``; ``q`` and ``−q`` are the same
  rotation), the Euclidean norm of the difference otherwise. Fields are ranked by the same
  difference in units of the base data's per-dim standard deviation (RMS over the field's
  dims), so a field measured in radians and one in metres compare fairly;
* **action dimensions**: mean absolute difference per dimension, ranked;
* **motion**, in the task's own terms where the states follow the simulated tasks' layout
  (the gripper's position first): the gripper's speed in metres per step, its paused steps,
  its direction (:func:`elicit_jax.elicit.plain.gripper_motion`). The operator *holds still
  where the base moves* when their gripper is still in at least half of the window's steps
  and the base's moves; *moves where the base holds still* in the opposite case. Other
  layouts (no known gripper) fall back to the mean per-step change of the normalised state
  (RMS over dims), with the same quarter-of-the-base rule.

:func:`explain_episode` returns one :class:`~elicit_jax.elicit.events.WindowFeedback` per
window, with a structured part (for a browser or a simulated person) and one line of text,
e.g. ``steps 0–9 (1−M 1.00): robot0_eef_quat differs by ~3.1 rad; action dyaw differs by
~0.9; you hold still where the base moves — compare base demo 3, steps 2–11``; where
:mod:`elicit_jax.elicit.plain` finds words for the difference (``you went right of the
pillar; the base goes left of it``) they lead and the numbers follow in brackets.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from elicit_jax.compat.feedback import episode_feedback, normalizer
from elicit_jax.elicit.events import FieldDifference, WindowFeedback
from elicit_jax.elicit.plain import gripper_motion, motion_kind, plain_words, sim_layout

STILL_RATIO = 0.25
MOTION_FLOOR = 0.01
"""Per-step normalised state change below which a segment counts as not moving at all."""


def _align(segment: np.ndarray, length: int) -> np.ndarray:
    """``segment (S, D)`` resampled to ``length`` rows by nearest index on an even grid."""
    idx = np.rint(np.linspace(0, len(segment) - 1, length)).astype(int)
    return segment[idx]


def _is_quaternion(name: str, size: int) -> bool:
    return size == 4 and "quat" in name.lower()


def _rotation_angle(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(T,) angle (rad) between the rotations of quaternions ``q, p (T, 4)``."""
    qn = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
    pn = p / np.maximum(np.linalg.norm(p, axis=1, keepdims=True), 1e-12)
    dot = np.clip(np.abs(np.sum(qn * pn, axis=1)), 0.0, 1.0)
    return 2.0 * np.arccos(dot)


def field_differences(
    op: np.ndarray, base: np.ndarray, fields: Sequence[Any], std: np.ndarray
) -> list[FieldDifference]:
    """Per observation field, how much the window ``op (W, O)`` differs from ``base (W, O)``.

    Args:
      fields: ``ObsField``-like objects (``name``, ``start``, ``stop``); empty: one field per
        dimension, named ``obs[i]``.
      std: (O,) the base data's per-dim std.

    Returns:
      Differences, largest normalised difference first.
    """
    spans = [(f.name, f.start, f.stop) for f in fields] or [
        (f"obs[{i}]", i, i + 1) for i in range(op.shape[1])
    ]
    out = []
    for name, a, b in spans:
        o, p = op[:, a:b], base[:, a:b]
        if _is_quaternion(name, b - a):
            flip = np.sum(o * p, axis=1, keepdims=True) < 0
            p = np.where(flip, -p, p)
            diff, unit = float(_rotation_angle(o, p).mean()), "rad"
        else:
            diff, unit = float(np.linalg.norm(o - p, axis=1).mean()), ""
        norm = float(np.sqrt(np.mean(((o - p) / std[a:b]) ** 2, axis=1)).mean())
        out.append(FieldDifference(name, "obs", diff, norm, unit))
    return sorted(out, key=lambda d: -d.normalized)


def action_differences(
    op: np.ndarray, base: np.ndarray, names: Sequence[str] | None = None
) -> list[FieldDifference]:
    """Per action dimension, the mean absolute difference of ``op (W, A)`` and ``base (W, A)``,
    largest first; ``names`` default to ``a0, a1, ...``."""
    names = list(names) if names else [f"a{i}" for i in range(op.shape[1])]
    diff = np.abs(op - base).mean(axis=0)
    out = [
        FieldDifference(n, "action", float(d), float(d)) for n, d in zip(names, diff, strict=True)
    ]
    return sorted(out, key=lambda d: -d.normalized)


def motion(states: np.ndarray, std: np.ndarray) -> float:
    """Mean per-step change of normalised states ``(T, O)`` (RMS over dims); 0 for T < 2."""
    if len(states) < 2:
        return 0.0
    step = np.diff(states, axis=0) / std
    return float(np.sqrt(np.mean(step**2, axis=1)).mean())


def _motion_kind(op: float, base: float) -> str:
    if base > MOTION_FLOOR and op < STILL_RATIO * base:
        return "still"
    if op > MOTION_FLOOR and base < STILL_RATIO * op:
        return "moving"
    return ""


def _fmt(d: FieldDifference) -> str:
    return f"{d.difference:.2g} {d.unit}".rstrip()


def window_text(fb: WindowFeedback, top: int = 2) -> str:
    """The one-line explanation of a window: its plain words first when it has any (the
    numbers follow in brackets), else the numbers."""
    parts = []
    fields = [d for d in fb.fields[:top] if d.normalized > 0]
    if fields:
        first, *rest = fields
        line = f"{first.name} differs by ~{_fmt(first)}"
        line += "".join(f", {d.name} by ~{_fmt(d)}" for d in rest)
        parts.append(line)
    if fb.actions and fb.actions[0].difference > 0:
        a = fb.actions[0]
        parts.append(f"action {a.name} differs by ~{a.difference:.2g}")
    if fb.motion == "still":
        parts.append("you hold still where the base moves")
    elif fb.motion == "moving":
        parts.append("you move where the base holds still")
    body = "; ".join(parts) or "close to the base demonstration"
    compare = f"compare base demo {fb.base_episode}, steps {fb.base_start}–{fb.base_stop - 1}"
    if fb.plain:
        return (
            f"steps {fb.start}–{fb.stop - 1}: {'; '.join(fb.plain)} — {compare} "
            f"(1−M {fb.incompatibility:.2f}; {body})"
        )
    return f"steps {fb.start}–{fb.stop - 1} (1−M {fb.incompatibility:.2f}): {body} — {compare}"


def explain_episode(
    compatibility: np.ndarray,
    obs: np.ndarray,
    action: np.ndarray,
    base: Any,
    *,
    action_names: Sequence[str] | None = None,
    window: int = 10,
    k: int = 3,
    method: str = "l2",
    stats: tuple[np.ndarray, np.ndarray] | None = None,
) -> list[WindowFeedback]:
    """The ``k`` worst windows of a demonstration, each with its base segment and what differs.

    Args:
      compatibility: (T,) M of each scored step.
      obs: (T, O) the states of those steps.
      action: (T, A) the operator's actions.
      base: the base :class:`~elicit_jax.data.demos.Demos`.
      action_names: names of the action dimensions (default ``a0, a1, ...``).
      window: window length.
      k: number of windows.
      method: retrieval, ``l2`` (paper) or ``dtw`` (original code).
      stats: the base states' (mean, std) if already computed.

    Returns:
      One :class:`WindowFeedback` per window, worst first.
    """
    obs, action = np.asarray(obs, np.float64), np.asarray(action, np.float64)
    _, std = stats if stats is not None else normalizer(base.obs)
    rows = {e: (s, t) for e, s, t in base.episode_bounds()}
    task = str(getattr(base, "task", ""))
    out = []
    for f in episode_feedback(compatibility, obs, base, window=window, k=k, method=method):
        w = f.window
        s0, s1 = rows[f.base_episode]
        b_obs = np.asarray(base.obs[s0 + f.base_start : s0 + f.base_stop], np.float64)
        b_act = np.asarray(base.action[s0 + f.base_start : s0 + f.base_stop], np.float64)
        o_obs, o_act = obs[w.start : w.stop], action[w.start : w.stop]
        n = len(o_obs)
        if sim_layout(base.obs_fields, obs.shape[1]):  # the gripper's own motion, in m
            gm_op, gm_base = gripper_motion(o_obs), gripper_motion(b_obs)
            op_motion, base_motion = gm_op.speed, gm_base.speed
            kind = motion_kind(gm_op, gm_base)
        else:
            op_motion, base_motion = motion(o_obs, std), motion(b_obs, std)
            kind = _motion_kind(op_motion, base_motion)
        b_aligned = _align(b_obs, n)
        fb = WindowFeedback(
            start=w.start,
            stop=w.stop,
            incompatibility=float(w.score),
            base_episode=int(f.base_episode),
            base_start=int(f.base_start),
            base_stop=int(f.base_stop),
            distance=float(f.distance),
            fields=tuple(field_differences(o_obs, b_aligned, base.obs_fields, std)),
            actions=tuple(action_differences(o_act, _align(b_act, n), action_names)),
            operator_motion=op_motion,
            base_motion=base_motion,
            motion=kind,
            text="",
            plain=plain_words(
                task, base.obs_fields, o_obs, b_aligned, obs, base.obs[s0:s1], kind, b_obs
            ),
        )
        out.append(_with_text(fb))
    return out


def _with_text(fb: WindowFeedback) -> WindowFeedback:
    import dataclasses

    return dataclasses.replace(fb, text=window_text(fb))


def summary_text(
    verdict: str, n_incompatible: int, scored: int, rule: str, feedback: Sequence[WindowFeedback]
) -> str:
    """One line: the verdict, the counts, the rule and the worst window's explanation."""
    frac = n_incompatible / scored if scored else 0.0
    line = f"{verdict}: {n_incompatible} of {scored} pairs incompatible ({100 * frac:.1f}%; {rule})"
    if feedback:
        line += f"; worst {feedback[0].text}"
    return line
