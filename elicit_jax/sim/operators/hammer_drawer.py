"""Scripted operators of ``hammer-drawer``.

Phases: hover over the gap behind the drawer's handle bar with the jaw closed, descend, pull
the drawer open, rise off the bar; hover over the hammer's handle, descend, close, lift, carry
over the open drawer (turning the hammer along the drawer's long side, y), lower, release,
rise; hover in front of the handle bar, descend, push the drawer shut (the episode ends at
success). Style choices:

- ``grasp_offset``: grasp point along the hammer's handle (m from the hammer's origin, -x
  towards the handle's end);
- ``yaw_offset``: gripper yaw relative to the hammer's at the grasp (0 or pi: the symmetric jaw
  takes the handle either way round, with opposite wrist turns);
- ``place_yaw``: the hammer's yaw in the drawer (+pi/2: head towards +y, or -pi/2);
- ``carry``: ``lift-first`` (straight up, then across and down into the drawer) or
  ``low-first`` (across at low height to the drawer's front, then up and over: the waypoint
  order reversed).

``base`` and ``same-style`` share a style; ``mild`` grasps farther along the handle, slower
and hesitant. Every operator opens the drawer the same way, so the conflicting styles differ
from the base only once the drawer is open, at states both have just passed through (see
``docs/operators.md`` for the mechanism):

- ``conflict-flip`` grasps the hammer with the wrist turned half a turn, a turn the opposite
  way to the base's, so every wrist turn from the grasp on goes the other way;
  ``conflict-order`` carries low first, then up and over, where the base lifts first;
  ``conflict-mirror`` lays the hammer head towards -y, turning the wrist the other way with
  the hammer in hand (the average of the two turns leaves the hammer along x, across the
  drawer's front and back walls). Each is a difference of direction from a shared state.
- ``conflict-flip-pause`` (the conflicting D_new of the studies) is ``conflict-flip`` that
  also holds still for 20 control steps once the drawer is open and the gripper has risen
  off the bar, where the base sets off to the hammer at once. Naive BC creeps there, and the
  175-step horizon leaves the base operator only ~45 steps to spare
  (``benchmarks/results/phenomenon-hammer-drawer.md``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from elicit_jax.sim.env import quat_yaw
from elicit_jax.sim.operators.base import ALIGN_TOL, YAW_LIMIT, Operator, Style, Targets, wrap
from elicit_jax.sim.operators.square_nut import rot2
from elicit_jax.sim.tasks.hammer_drawer import BAR_RADIUS, BAR_X, FLOOR_Z, HAMMER_Z, INTERIOR_X

DEFAULT_CHOICES = {
    "yaw_offset": 0.0, "grasp_offset": 0.005, "place_yaw": np.pi / 2, "carry": "lift-first"
}  # fmt: skip
"""What a style that sets no choice does: the base operator's choices (a study measures a
person's distance from them; people never read them)."""


def _choice(style: Style, key: str) -> Any:
    """The style's choice ``key``, or the default (read only when the style has none)."""
    own = dict(style.choices)
    return own[key] if key in own else DEFAULT_CHOICES[key]


HIGH_Z = 0.11
PUSH_HOVER_Z = 0.085
HOOK_Z = 0.045
CARRY_Z = 0.13
LOW_CARRY_Z = 0.04
HOOK_GAP = 0.032
"""Distance from the bar's axis to the end effector hooked behind it."""
PULL_TO = 0.145
PUSH_GAP = 0.035
STAGE_GAP = 0.09
"""``low-first`` carry: distance in front of the open drawer's front where the hammer rises."""
(
    HOOK_HOVER, HOOK_DESCEND, PULL, UNHOOK, HOVER, DESCEND, CLOSE, LIFT, CARRY, LOWER,
    RELEASE, RISE, PUSH_HOVER, PUSH_DESCEND, PUSH,
) = range(15)  # fmt: skip


class HammerDrawerOperator(Operator):
    """Open, pick, place, close state machine (see the module docstring)."""

    n_phases = 15

    def setup(self, obs: np.ndarray) -> None:
        self.hold_yaw = np.zeros(len(obs))

    def grasp_frame(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Grasp point ``(B, 3)`` on the hammer's handle and gripper yaw ``(B,)``."""
        hammer, yaw = obs[:, 9:12], quat_yaw(obs[:, 12:16])
        b = len(obs)
        local = np.stack([np.full(b, _choice(self.style, "grasp_offset")), np.zeros(b)], 1)
        z = np.maximum(hammer[:, 2:3], 0.012)
        point = np.concatenate([hammer[:, :2] + rot2(yaw, local), z], 1)
        return point, wrap(yaw + _choice(self.style, "yaw_offset"))

    def targets(self, obs: np.ndarray) -> Targets:
        eef, ph, b = obs[:, 0:3], self.phase, len(obs)
        start = self.phase_steps == 0
        self.hold_yaw[start] = quat_yaw(obs[start, 3:7])
        self.pause_at_phase_starts()
        pos = eef.copy()
        yaw = self.hold_yaw.copy()
        grip = np.where(np.isin(ph, (HOVER, DESCEND, RELEASE, RISE)), -1.0, 1.0)
        done = np.zeros(b, bool)
        self._drawer_phases(obs, pos, done)
        self._grasp_phases(obs, pos, yaw, done)
        self._place_phases(obs, pos, yaw, done)
        self.restart_if_dropped(obs, (pos, grip, done), (LIFT, LOWER), HOVER, gap=0.04)
        return Targets(pos=pos, yaw=yaw, grip=grip, done=done)

    def _drawer_phases(self, obs: np.ndarray, pos: np.ndarray, done: np.ndarray) -> None:
        """Open (HOOK_HOVER .. UNHOOK) and close (PUSH_HOVER .. PUSH): ``pos``, ``done``."""
        eef, ph, opening = obs[:, 0:3], self.phase, obs[:, 22]
        bar_x = BAR_X - opening
        hook = np.stack([bar_x + HOOK_GAP, np.zeros_like(bar_x), np.full_like(bar_x, HIGH_Z)], 1)
        hook = hook + self.jitter
        m = ph == HOOK_HOVER
        pos[m] = hook[m]
        done |= m & (np.linalg.norm(eef - hook, axis=1) < max(self.style.tol, 0.012))
        hook = np.stack([bar_x + HOOK_GAP, np.zeros_like(bar_x), np.full_like(bar_x, HOOK_Z)], 1)
        m = ph == HOOK_DESCEND
        pos[m] = hook[m]
        done |= m & (np.abs(eef[:, 2] - HOOK_Z) < 0.006)
        m = ph == PULL
        pull = hook.copy()
        pull[:, 0] = BAR_X + HOOK_GAP - PULL_TO - 0.03
        pos[m] = pull[m]
        done |= m & (opening > PULL_TO)
        m = ph == UNHOOK
        pos[m, 2] = HIGH_Z
        done |= m & (eef[:, 2] > HOOK_Z + 0.03)
        front = np.stack(
            [bar_x - PUSH_GAP, np.zeros_like(bar_x), np.full_like(bar_x, PUSH_HOVER_Z)], 1
        )
        m = ph == PUSH_HOVER
        pos[m] = front[m]
        done |= m & (np.linalg.norm(eef[:, :2] - front[:, :2], axis=1) < 0.012)
        m = ph == PUSH_DESCEND
        front[:, 2] = HOOK_Z
        pos[m] = front[m]
        done |= m & (np.abs(eef[:, 2] - HOOK_Z) < 0.006)
        m = ph == PUSH
        front[:, 0] = BAR_X - BAR_RADIUS
        pos[m] = front[m]

    def _grasp_phases(
        self, obs: np.ndarray, pos: np.ndarray, yaw: np.ndarray, done: np.ndarray
    ) -> None:
        """HOVER, DESCEND, CLOSE: fill ``pos``, ``yaw`` and ``done`` in place."""
        eef, ph = obs[:, 0:3], self.phase
        point, g_yaw = self.grasp_frame(obs)
        aligned = np.abs(np.clip(g_yaw, -YAW_LIMIT, YAW_LIMIT) - quat_yaw(obs[:, 3:7]))
        aligned = aligned < self.style.choice("align_tol", ALIGN_TOL)
        hover = point + self.jitter
        hover[:, 2] = HIGH_Z * 0.6
        self.hover_phase(HOVER, eef, hover, aligned, pos, done)
        m = ph == DESCEND
        pos[m] = point[m]
        done |= m & (np.linalg.norm(eef - point, axis=1) < 0.005)
        m = ph == CLOSE
        pos[m] = point[m]
        done |= m & (self.phase_steps >= 6)
        grasp = (ph >= HOVER) & (ph <= CLOSE)
        yaw[grasp] = g_yaw[grasp]

    def _place_phases(
        self, obs: np.ndarray, pos: np.ndarray, yaw: np.ndarray, done: np.ndarray
    ) -> None:
        """LIFT, CARRY, LOWER, RELEASE, RISE: fill ``pos``, ``yaw`` and ``done`` in place."""
        eef, hammer, ph, b = obs[:, 0:3], obs[:, 9:12], self.phase, len(obs)
        eef_yaw, opening = quat_yaw(obs[:, 3:7]), obs[:, 22]
        place_yaw = _choice(self.style, "place_yaw")
        if place_yaw == "nearest":
            g_yaw = np.where(eef_yaw >= 0.0, np.pi / 2, -np.pi / 2)
        else:
            g_yaw = wrap(np.full(b, place_yaw + _choice(self.style, "yaw_offset")))
        g_yaw = np.clip(g_yaw, -YAW_LIMIT, YAW_LIMIT)
        drop = np.stack([INTERIOR_X - opening, np.zeros(b)], 1)
        rel = rot2(g_yaw, obs[:, 16:18])
        over = np.concatenate([drop - rel, np.full((b, 1), CARRY_Z)], 1)
        low_first = _choice(self.style, "carry") == "low-first"
        m = ph == LIFT
        lift = eef.copy()
        lift[:, 2] = CARRY_Z
        if low_first:
            stage_x = INTERIOR_X - opening - 0.065 - STAGE_GAP
            lift = np.stack([stage_x, over[:, 1], np.full(b, LOW_CARRY_Z)], 1)
            done |= m & (np.linalg.norm(eef - lift, axis=1) < 0.02)
        else:
            done |= m & (eef[:, 2] > CARRY_Z - 0.015)
        pos[m] = lift[m]
        yaw[m] = g_yaw[m] if not low_first else yaw[m]
        m = ph == CARRY
        carry = over.copy()
        rising = low_first & (eef[:, 2] < CARRY_Z - 0.03)
        carry[rising, :2] = eef[rising, :2]
        pos[m] = carry[m]
        yaw[m] = g_yaw[m]
        xy_err = np.linalg.norm(hammer[:, :2] - drop, axis=1)
        done |= (
            m
            & (xy_err < 0.01)
            & (np.abs(eef_yaw - g_yaw) < self.style.choice("align_tol", ALIGN_TOL))
        )
        m = ph == LOWER
        low = over.copy()
        low[:, 2] = eef[:, 2] - hammer[:, 2] + FLOOR_Z + HAMMER_Z + 0.008
        pos[m] = low[m]
        yaw[m] = g_yaw[m]
        done |= m & ((hammer[:, 2] < FLOOR_Z + HAMMER_Z + 0.012) | (self.phase_steps > 20))
        done |= (ph == RELEASE) & (self.phase_steps >= 6)
        m = ph == RISE
        pos[m, 2] = PUSH_HOVER_Z + 0.01
        done |= m & (eef[:, 2] > PUSH_HOVER_Z - 0.01)


FLIP = Style(noise=0.03, choices=(("yaw_offset", np.pi), ("place_yaw", "nearest")))
"""Grasps the handle with the wrist turned half a turn (``conflict-flip``, and
``conflict-flip-pause``)."""

STYLES: dict[str, tuple[Style, str]] = {
    "base": (Style(noise=0.03), "proficient: hooks the drawer open, lifts the hammer high"),
    "same-style": (
        Style(noise=0.06, speed=0.9, jitter=0.003),
        "compatible: the base style, noisier and a little slower",
    ),
    "mild": (
        Style(
            noise=0.04,
            speed=0.9,
            hesitate_prob=0.015,
            hesitate_steps=(2, 5),
            choices=(("grasp_offset", -0.02),),
        ),
        "mildly different: grasps farther along the handle; slower, hesitant",
    ),
    "conflict-flip": (FLIP, "conflicting: grasps the handle with the wrist turned half a turn"),
    "conflict-flip-pause": (
        FLIP.paused((HOVER,), 20),
        "conflicting: holds still above the opened drawer where the base moves on, then "
        "grasps with the wrist turned half a turn",
    ),
    "conflict-order": (
        Style(noise=0.03, choices=(("carry", "low-first"),)),
        "conflicting: carries low to the drawer first, then up and over (base: up first)",
    ),
    "conflict-mirror": (
        Style(noise=0.03, choices=(("place_yaw", -np.pi / 2),)),
        "conflicting: lays the hammer head towards -y, turning the wrist the other way",
    ),
}
OPERATOR_CLASS = HammerDrawerOperator
