"""Scripted operators of ``robosuite-square`` and ``robosuite-round`` (Panda, OSC_POSE).

The same phases and style families as ``square-nut``: hover over the handle, descend, close,
lift, carry over the peg, lower, release, retreat; proportional control of the end effector
towards each phase's target. Geometry the operator knows (as a person reading the task would):
the table's height, the peg's position and height, where the handle sits on the nut. It reads
everything else from the observation (nut pose, end-effector pose, fingers).

The end effector points down; its yaw is the heading of its x axis in the table plane, and
the jaw closes across it. The jaw is symmetric, so the handle can be taken with two wrist
yaws half a turn apart:

- ``base`` (and ``same-style``, ``mild``) turns to the nearer one (at most a quarter turn);
- ``yaw_offset = pi`` (``conflict-flip``, ``conflict-flip-pause``) turns to the other one,
  the opposite way round, when the Panda's wrist range (about -1.9 .. +2.9 rad of turn from
  its start pose) allows that; otherwise it takes the nearer one as well. Measured over
  initial states: see docs/operators.md.
- ``pause_at`` / ``pause_steps``: hold still on entering those phases (the conflicting D_new
  of the studies holds still 40 steps at the start, above the handle and above the peg:
  the base takes ~170 steps here, so 60-step pauses left too little of the 500-step horizon
  for a second try after a slip);
- ``approach = tip``: come down beside the handle's free end and slide in along it;
- ``approach = down-first`` (``conflict-down``): go straight down first, to ``LOW_ABOVE``
  over the grasp height, then across, low, to over the grasp point, then down: the paper's
  "down, then across", where the base goes across (at ``HOVER_ABOVE``), then down. It
  differs from the base from the first step of every initial state;
- ``grasp_offset``: grasp point along the handle, from the nut's centre (m).
"""

from __future__ import annotations

import numpy as np

from elicit_jax.sim.operators.base import Operator, Style, Targets, wrap
from elicit_jax.sim.operators.nut_traits import measure as measure_nut_traits
from elicit_jax.sim.operators.square_nut import (
    CARRY,
    CLOSE,
    DESCEND,
    FLIP,
    HOVER,
    LIFT,
    LOWER,
    RELEASE,
    RETREAT,
    rot2,
)
from elicit_jax.sim.operators.square_nut import STYLES as SQUARE_NUT_STYLES

TABLE_Z = 0.82
NUT_REST_Z = 0.83
HOVER_ABOVE = 0.06
LOW_ABOVE = 0.03
"""Height (m) above the grasp point at which ``approach = down-first`` goes across."""
CARRY_Z = 1.02
PEG_TOP = 0.95
TURN_RANGE = (-1.8, 2.8)
"""Wrist turn (rad, + counter-clockwise seen from above) the operator allows from its start
pose: the Panda's last joint starts near pi/4 within a range of +-2.9 rad."""


def eef_yaw(quat_xyzw: np.ndarray) -> np.ndarray:
    """(B,) heading of the end effector's x axis in the table plane (robosuite x-y-z-w)."""
    x, y, z, w = (quat_xyzw[:, i] for i in range(4))
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r10 = 2.0 * (x * y + w * z)
    return np.arctan2(r10, r00)


def nut_yaw(quat_xyzw: np.ndarray) -> np.ndarray:
    """(B,) yaw of the nut (it rests flat) from its x-y-z-w quaternion."""
    return eef_yaw(quat_xyzw)


class RobosuiteNutOperator(Operator):
    """Pick-and-place state machine on robosuite (see the module docstring)."""

    n_phases = 8

    def setup(self, obs: np.ndarray) -> None:
        b = len(obs)
        self.start_yaw = eef_yaw(obs[:, 3:7])
        handle = nut_yaw(obs[:, 19:23])
        near = wrap(2 * (handle - self.start_yaw)) / 2  # nearest jaw yaw: a quarter turn at most
        turn = near
        if abs(self.style.choice("yaw_offset", 0.0)) > 1.0:
            far = near - np.pi * np.sign(near + 1e-9)
            ok = (far > TURN_RANGE[0]) & (far < TURN_RANGE[1])
            turn = np.where(ok, far, near)
        self.turn = turn
        self.grip_offset = np.zeros((b, 3))
        approach = self.style.choice("approach", "above")
        self.down_first = np.full(b, approach == "down-first")
        self.slide_in = np.full(b, approach == "tip")
        self.lowered = np.zeros(b, bool)

    def yaw_error(self, target: np.ndarray, obs: np.ndarray) -> np.ndarray:
        turned = wrap(eef_yaw(obs[:, 3:7]) - self.start_yaw)
        # the turn so far, unwrapped towards the planned turn (it never exceeds a half turn
        # by more than the tolerance)
        turned = np.where(np.abs(turned - target) > np.pi, turned + 2 * np.pi * np.sign(target),
                          turned)  # fmt: skip
        return target - turned

    def grasp_point(self, obs: np.ndarray) -> np.ndarray:
        """(B, 3) grasp point on the handle."""
        nut, yaw = obs[:, 16:19], nut_yaw(obs[:, 19:23])
        b = len(obs)
        off = self.style.choice("grasp_offset", self.task.handle_offset)  # type: ignore[attr-defined]
        local = np.stack([np.full(b, off), np.zeros(b)], 1)
        z = np.maximum(nut[:, 2:3], NUT_REST_Z) + 0.002
        return np.concatenate([nut[:, :2] + rot2(yaw, local), z], 1)

    def targets(self, obs: np.ndarray) -> Targets:
        eef, ph = obs[:, 0:3], self.phase
        pos = eef.copy()
        grip = np.where((ph >= CLOSE) & (ph < RELEASE), 1.0, -1.0)
        done = np.zeros(len(obs), bool)
        self.pause_at_phase_starts()
        aligned = np.abs(self.yaw_error(self.turn, obs)) < 0.06
        self._grasp_phases(obs, aligned, pos, done)
        self._place_phases(obs, pos, done)
        self.restart_if_dropped_nut(obs, pos, grip, done)
        turned = wrap(eef_yaw(obs[:, 3:7]) - self.start_yaw)
        yaw = np.where(ph <= CLOSE, self.turn, turned - self.peg_misalignment(obs))
        return Targets(pos=pos, yaw=yaw, grip=grip, done=done)

    def peg_misalignment(self, obs: np.ndarray) -> np.ndarray:
        """(B,) nut yaw off the peg's symmetry (a square peg: quarter turns; round: none)."""
        sym = self.task.peg_symmetry  # type: ignore[attr-defined]
        if sym <= 0:
            return np.zeros(len(obs))
        y = nut_yaw(obs[:, 19:23])
        return (y + sym / 2) % sym - sym / 2

    def restart_if_dropped_nut(
        self, obs: np.ndarray, pos: np.ndarray, grip: np.ndarray, done: np.ndarray
    ) -> None:
        """Back to HOVER with the jaw open when the nut slipped out while carried."""
        eef, nut, ph = obs[:, 0:3], obs[:, 16:19], self.phase
        slipped = (ph >= LIFT) & (ph <= LOWER) & (eef[:, 2] - nut[:, 2] > 0.05)
        self.phase[slipped] = HOVER
        self.phase_steps[slipped] = 0
        grip[slipped] = -1.0
        done[slipped] = False
        pos[slipped] = eef[slipped] + np.array([0.0, 0.0, 0.02])

    def _grasp_phases(
        self, obs: np.ndarray, aligned: np.ndarray, pos: np.ndarray, done: np.ndarray
    ) -> None:
        """HOVER, DESCEND, CLOSE: fill ``pos`` and ``done`` in place."""
        eef, ph, b = obs[:, 0:3], self.phase, len(obs)
        point = self.grasp_point(obs)
        tip = point.copy()
        tip[:, :2] += rot2(nut_yaw(obs[:, 19:23]), np.tile([[0.06, 0.0]], (b, 1)))
        hover = np.where(self.slide_in[:, None], tip, point)
        far = np.linalg.norm(eef[:, :2] - hover[:, :2], axis=1) > 0.015
        above = np.where(self.down_first, LOW_ABOVE, HOVER_ABOVE)
        hover[:, 2] = np.where(self.slide_in & ~far, point[:, 2], point[:, 2] + above)
        # down, then across: straight down from where the episode starts, then across low
        self.lowered |= self.down_first & (eef[:, 2] < point[:, 2] + LOW_ABOVE + 0.01)
        first = self.down_first & ~self.lowered
        start_xy = self.start_obs[:, 0:2]
        hover[first] = np.concatenate([start_xy[first], point[first, 2:] + LOW_ABOVE], 1)
        self.hover_phase(HOVER, eef, hover + self.jitter, aligned, pos, done)
        done &= ~first  # coming down is not the hover: it ends over the grasp point
        m = ph == DESCEND
        pos[m] = point[m]
        err = eef - point
        close = np.linalg.norm(err, axis=1) < 0.008
        # the fingers can rest on the table or nut a few mm short of the point: go on once
        # over it and no longer descending
        settled = (np.linalg.norm(err[:, :2], axis=1) < 0.01) & (np.abs(err[:, 2]) < 0.015)
        done |= m & (close | (settled & (self.phase_steps > 20)))
        m = ph == CLOSE
        pos[m] = point[m]
        done |= m & (self.phase_steps >= 8)

    def _place_phases(self, obs: np.ndarray, pos: np.ndarray, done: np.ndarray) -> None:
        """LIFT, CARRY, LOWER, RELEASE, RETREAT: fill ``pos`` and ``done`` in place."""
        eef, nut, ph, b = obs[:, 0:3], obs[:, 16:19], self.phase, len(obs)
        peg_xy = np.asarray(self.task.peg_xy)  # type: ignore[attr-defined]
        m = ph == LIFT
        self.grip_offset[m] = (eef - nut)[m]
        lift = eef.copy()
        lift[:, 2] = CARRY_Z
        pos[m] = lift[m]
        done |= m & (eef[:, 2] > CARRY_Z - 0.015)
        over = np.concatenate([peg_xy + (eef - nut)[:, :2], np.full((b, 1), CARRY_Z)], 1)
        m = ph == CARRY
        pos[m] = over[m]
        square = np.abs(self.peg_misalignment(obs)) < 0.05
        done |= m & (np.linalg.norm(nut[:, :2] - peg_xy, axis=1) < 0.006) & square
        m = ph == LOWER
        over[:, 2] = eef[:, 2] - 0.03
        pos[m] = over[m]
        done |= m & (nut[:, 2] < TABLE_Z + 0.04)
        done |= (ph == RELEASE) & (self.phase_steps >= 6)
        up = eef.copy()
        up[:, 2] = CARRY_Z
        pos[ph == RETREAT] = up[ph == RETREAT]


STYLES: dict[str, tuple[Style, str]] = {
    "base": SQUARE_NUT_STYLES["base"],
    "same-style": SQUARE_NUT_STYLES["same-style"],
    "mild": (
        Style(noise=0.04, speed=0.8, hesitate_prob=0.02, choices=(("approach", "tip"),)),
        "mildly different: down beside the handle tip, then slides in; slower, hesitant",
    ),
    "conflict-flip": (
        FLIP,
        "conflicting: grasps the handle with the wrist turned half a turn (where it can)",
    ),
    "conflict-flip-pause": (
        FLIP.paused((HOVER, DESCEND, LOWER), 40),
        "conflicting: wrist turned half a turn (where it can), and stops still before each move",
    ),
    "conflict-down": (
        Style(noise=0.03, speed=0.8, choices=(("approach", "down-first"),)),
        "conflicting: down first, then across low to the handle (the base: across, then down)",
    ),
}
"""``base`` and ``same-style`` are the square nut's; ``mild`` has no grasp offset, and the
pauses of ``conflict-flip-pause`` are shorter (see the module docstring)."""
OPERATOR_CLASS = RobosuiteNutOperator
MEASURE_TRAITS = measure_nut_traits
"""What each demo did (grasp side, approach, pauses), measured from its own states."""
