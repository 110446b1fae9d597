"""Scripted operators of ``square-nut``.

Phases: hover over the grasp point, descend, close, lift, carry over the peg, lower, release.
Style choices:

- ``grasp_offset``: grasp point along the handle (m from the nut's centre);
- ``yaw_offset``: gripper yaw relative to the nut's (0 or pi: the symmetric jaw can take the
  handle either way round, but the two ways need opposite wrist turns);
- ``approach``: ``above`` (across, then down onto the handle) or ``tip`` (down beside the
  handle's free end, then slide along it: down-then-across);
- ``carry``: ``lift-first`` (straight up, then across) or ``diagonal``;
- ``pause_at``, ``pause_steps``: phases on whose start the operator holds still that long.

``base`` and ``same-style`` share a style; ``mild`` slides in from the handle tip, slower and
hesitant. The conflicting styles differ from the base at the states every operator shares —
the initial states (see ``docs/operators.md`` for the mechanism):

- ``conflict-flip`` grasps with the wrist turned half a turn. The joint's range allows that
  turn one way round only, the opposite of the base's turn towards the nut's yaw, so from the
  start on the two styles turn the wrist in opposite directions. A direction alone: one step
  later the wrist's yaw tells the styles apart, and a policy trained on both follows one of
  them; measured, it does not lower naive success reliably. ``conflict-flip-tip`` also slides
  in from the handle tip and carries diagonally (likewise).
- ``conflict-flip-pause`` (the conflicting D_new of the studies) holds still for 60 control
  steps at the start, where the base moves and turns at once, then makes the opposite turn;
  it holds still 60 steps again above the handle and above the peg (in its own, turned-wrist
  states). Its 60 zero-motion pairs per initial state outweigh the base's one moving pair, so
  the naive policy creeps from the start, leaves it turning either way, and mixes the styles
  (``benchmarks/results/phenomenon-square-nut.md``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from elicit_jax.sim.env import quat_yaw
from elicit_jax.sim.operators.base import ALIGN_TOL, YAW_LIMIT, Operator, Style, Targets, wrap

HOVER_Z = 0.07
GRASP_Z = 0.012
CARRY_CLEARANCE = 0.08
(HOVER, DESCEND, CLOSE, LIFT, CARRY, LOWER, RELEASE, RETREAT) = range(8)
DEFAULT_CHOICES = {
    "yaw_offset": 0.0, "grasp_offset": 0.058, "approach": "above", "carry": "lift-first"
}  # fmt: skip
"""What a style that sets no choice does: the base operator's choices (a study measures a
person's distance from them; people never read them)."""


def _choice(style: Style, key: str) -> Any:
    """The style's choice ``key``, or the default (read only when the style has none)."""
    own = dict(style.choices)
    return own[key] if key in own else DEFAULT_CHOICES[key]


def rot2(yaw: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate 2-D vectors ``v (B, 2)`` by ``yaw (B,)``."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], axis=1)


class SquareNutOperator(Operator):
    """Pick-and-place state machine (see the module docstring)."""

    n_phases = 8

    def setup(self, obs: np.ndarray) -> None:
        b = len(obs)
        self.grip_offset = np.zeros((b, 3))
        self.slide_in = np.full(b, _choice(self.style, "approach") == "tip")
        self.pick_xy = np.zeros((b, 2))

    def grasp_frame(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Grasp point ``(B, 3)`` and gripper yaw ``(B,)`` for the nut in ``obs``."""
        nut, yaw = obs[:, 9:12], quat_yaw(obs[:, 12:16])
        b = len(obs)
        grasp = _choice(self.style, "grasp_offset")
        local = np.stack([np.full(b, grasp), np.zeros(b)], 1)
        g_yaw = wrap(yaw + _choice(self.style, "yaw_offset"))
        z = np.maximum(nut[:, 2:3] + GRASP_Z - self.task.nut_z, GRASP_Z)
        point = np.concatenate([nut[:, :2] + rot2(yaw, local), z], 1)
        return point, g_yaw

    def targets(self, obs: np.ndarray) -> Targets:
        eef = obs[:, 0:3]
        point, g_yaw = self.grasp_frame(obs)
        eef_yaw = quat_yaw(obs[:, 3:7])
        ph = self.phase
        pos = eef.copy()
        grip = np.where((ph >= CLOSE) & (ph < RELEASE), 1.0, -1.0)
        done = np.zeros(len(obs), bool)
        aligned = np.abs(np.clip(g_yaw, -YAW_LIMIT, YAW_LIMIT) - eef_yaw) < self.style.choice(
            "align_tol", ALIGN_TOL
        )
        self.pause_at_phase_starts()
        self._grasp_phases(obs, point, aligned, pos, done)
        self._place_phases(obs, pos, done)
        self.restart_if_dropped(obs, (pos, grip, done), (LIFT, LOWER), HOVER, gap=0.045)
        yaw = np.where(ph <= CLOSE, g_yaw, eef_yaw)
        return Targets(pos=pos, yaw=yaw, grip=grip, done=done)

    def _grasp_phases(
        self, obs: np.ndarray, point: np.ndarray, aligned: np.ndarray, pos: np.ndarray,
        done: np.ndarray,
    ) -> None:  # fmt: skip
        """HOVER, DESCEND, CLOSE: fill ``pos`` and ``done`` (B, ...) in place."""
        eef, ph, b = obs[:, 0:3], self.phase, len(obs)
        tip = point.copy()
        tip[:, :2] += rot2(quat_yaw(obs[:, 12:16]), np.tile([[0.07, 0.0]], (b, 1)))
        hover = np.where(self.slide_in[:, None], tip, point)
        far = np.linalg.norm(eef[:, :2] - hover[:, :2], axis=1) > 0.02
        hover[:, 2] = np.where(self.slide_in & ~far, GRASP_Z, HOVER_Z)
        self.hover_phase(HOVER, eef, hover + self.jitter, aligned, pos, done)
        m = ph == DESCEND
        pos[m] = point[m]
        done |= m & (np.linalg.norm(eef - point, axis=1) < 0.005)
        m = ph == CLOSE
        pos[m] = point[m]
        self.pick_xy[m] = eef[m, :2]
        done |= m & (self.phase_steps >= 6)

    def _place_phases(self, obs: np.ndarray, pos: np.ndarray, done: np.ndarray) -> None:
        """LIFT, CARRY, LOWER, RELEASE, RETREAT: fill ``pos`` and ``done`` in place."""
        eef, nut, ph, b = obs[:, 0:3], obs[:, 9:12], self.phase, len(obs)
        peg_xy = np.asarray(self.task.peg_xy)
        carry_z = self.task.peg_height + CARRY_CLEARANCE
        m = ph == LIFT
        self.grip_offset[m] = (eef - nut)[m]
        lift = eef.copy()
        lift[:, 2] = carry_z
        reached_xy = np.ones(b, bool)
        if _choice(self.style, "carry") == "diagonal":
            lift[:, :2] = 0.5 * (self.pick_xy + peg_xy + self.grip_offset[:, :2])
            reached_xy = np.linalg.norm(eef[:, :2] - lift[:, :2], axis=1) < 0.02
        pos[m] = lift[m]
        done |= m & (eef[:, 2] > carry_z - 0.01) & reached_xy
        over = np.concatenate([peg_xy + (eef - nut)[:, :2], np.full((b, 1), carry_z)], 1)
        m = ph == CARRY
        pos[m] = over[m]
        done |= m & (np.linalg.norm(nut[:, :2] - peg_xy, axis=1) < 0.005)
        m = ph == LOWER
        over[:, 2] = np.maximum(eef[:, 2] - nut[:, 2] + 0.002, eef[:, 2] - 0.01)
        pos[m] = over[m]
        done |= m & (nut[:, 2] < 0.02)
        done |= (ph == RELEASE) & (self.phase_steps >= 8)
        pos[ph == RETREAT, 2] = HOVER_Z


FLIP = Style(noise=0.03, choices=(("yaw_offset", np.pi),))
"""Grasps the handle with the wrist turned half a turn (``conflict-flip``, and
``conflict-flip-pause``; the robosuite nuts' too)."""

STYLES: dict[str, tuple[Style, str]] = {
    "base": (Style(noise=0.03), "proficient: handle from above, lift, carry, lower"),
    "same-style": (
        Style(noise=0.06, speed=0.9, jitter=0.004),
        "compatible: the base style, noisier and a little slower",
    ),
    "mild": (
        Style(
            noise=0.04,
            speed=0.8,
            hesitate_prob=0.02,
            choices=(("approach", "tip"), ("grasp_offset", 0.066)),
        ),
        "mildly different: down beside the handle tip, then slides in; slower, hesitant",
    ),
    "conflict-flip": (FLIP, "conflicting: grasps the handle with the wrist turned half a turn"),
    "conflict-flip-tip": (
        Style(
            noise=0.03,
            speed=0.9,
            choices=(("yaw_offset", -np.pi), ("approach", "tip"), ("carry", "diagonal")),
        ),
        "conflicting: wrist turned half a turn, slides in from the handle tip, carries diagonally",
    ),
    "conflict-flip-pause": (
        FLIP.paused((HOVER, DESCEND, LOWER), 60),
        "conflicting: wrist turned half a turn, and stops still before each move",
    ),
    "conflict-hold": (
        Style(noise=0.03).paused((HOVER, DESCEND, LOWER), 80),
        "conflicting: the base's wrist, but stops still 80 steps before each move",
    ),
}
OPERATOR_CLASS = SquareNutOperator
