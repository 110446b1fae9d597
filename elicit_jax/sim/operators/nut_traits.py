"""What a robosuite nut demonstration did, measured from its own states and actions.

A study that calls an operator *conflicting* relies on its demos actually doing the thing that
conflicts with the base operator's. That is measured here per episode from the recorded
observations and actions alone: no operator, style or seed is consulted, so the same
measurement applies to imported human demonstrations.

Three traits (robosuite's low-dimensional observation: end effector at ``obs[0:3]``, its
x-y-z-w quaternion at ``obs[3:7]``, the nut at ``obs[16:19]``, its quaternion at ``obs[19:23]``):

- **grasp side**: the jaw is symmetric, so the handle can be taken at two wrist yaws half a
  turn apart. The *near* side is the one reachable with at most a quarter turn from the start
  pose; a demo grasps on the **far** side when the wrist turn it made by the moment the jaw
  closes differs from the near turn by more than a quarter turn.
- **approach**: the height of the end effector above its grasp position when it first came
  within ``APPROACH_RADIUS`` of it in the table plane. Coming across, then down (the base's
  way) arrives ~6 cm above it; sliding in along the handle after going down beside it (the
  paper's "down, then across") arrives less than ``SLIDE_HEIGHT`` above it.
- **down first**: half way across (the first step at half of its starting table-plane
  distance from its grasp position, when that distance is over ``DOWN_FIRST_MIN``), the end
  effector was already less than ``LOW_HEIGHT`` above its grasp position: down, then across.
  The base (and ``mild``) go across at ~6 cm above it and come down only at the handle: across,
  then down.
- **still start**: control steps at the start with no motion command (a pause where every
  other operator moves at once).

A demo *conflicts* with the base operator's way when it grasps on the far side or comes down
first: the base operator (at most a quarter turn, across then down) does neither. Sliding in
along the handle at the end of an across-then-down approach (``mild``) is recorded
(``slide_in``) but not counted as a conflict.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from elicit_jax.sim.operators.base import wrap

APPROACH_RADIUS = 0.02
"""Table-plane distance (m) from the grasp position at which the approach height is read."""
SLIDE_HEIGHT = 0.025
"""Approach height (m) below which a demo slid in along the handle (the base arrives ~0.06)."""
DOWN_FIRST_MIN = 0.04
"""Smallest starting table-plane distance (m) from the grasp position that has a half way."""
LOW_HEIGHT = 0.048
"""Height (m) above the grasp position under which the way across counts as low."""
STILL_EPS = 1e-6
"""Largest motion command (any of the 6 arm dims) that counts as no motion."""


@dataclasses.dataclass(frozen=True)
class NutTraits:
    """One demonstration's measured traits (see the module docstring).

    Attributes:
      grasp_step: first step whose gripper command closes the jaw (-1: the jaw never closes).
      grasp_turn: wrist turn (rad, unwrapped) from the start pose at ``grasp_step``.
      near_turn: the turn (rad) to the near grasp side from the start pose.
      far_grasp: the jaw closed on the far side.
      approach_height: end effector height (m) above its grasp position on first coming within
        ``APPROACH_RADIUS`` of it in the table plane (NaN when the jaw never closes).
      slide_in: the approach height is below ``SLIDE_HEIGHT``.
      down_first: the end effector came down before going across (module docstring).
      still_start: leading control steps with no motion command.
    """

    grasp_step: int
    grasp_turn: float
    near_turn: float
    far_grasp: bool
    approach_height: float
    slide_in: bool
    down_first: bool
    still_start: int

    @property
    def conflicts(self) -> bool:
        """The demo grasps or approaches in a way the base operator never does."""
        return self.far_grasp or self.down_first


def _yaw(quat_xyzw: np.ndarray) -> np.ndarray:
    """(T,) heading of the x axis in the table plane of x-y-z-w quaternions ``(T, 4)``."""
    x, y, z, w = (quat_xyzw[:, i] for i in range(4))
    return np.arctan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))


def measure(obs: np.ndarray, action: np.ndarray) -> NutTraits:
    """Measure one episode.

    Args:
      obs: (T, 23) robosuite nut observations (layout in the module docstring).
      action: (T, 7) actions; ``action[:, 6] > 0`` closes the jaw.

    Returns:
      The episode's :class:`NutTraits`.
    """
    obs = np.asarray(obs, np.float64)
    action = np.asarray(action, np.float64)
    moving = np.abs(action[:, :6]).max(axis=1) > STILL_EPS
    still = int(np.argmax(moving)) if moving.any() else len(action)
    yaw = np.unwrap(_yaw(obs[:, 3:7]))
    start = yaw[0]
    near = float(wrap(np.array(2.0 * (_yaw(obs[:1, 19:23])[0] - start))) / 2.0)
    closing = np.flatnonzero(action[:, 6] > 0)
    if len(closing) == 0:
        return NutTraits(-1, float("nan"), near, False, float("nan"), False, False, still)
    g = int(closing[0])
    turn = float(yaw[g] - start)
    far = abs(turn - near) > np.pi / 2
    at_grasp = obs[g, 0:3]
    dist = np.linalg.norm(obs[: g + 1, 0:2] - at_grasp[:2], axis=1)
    first = int(np.argmax(dist < APPROACH_RADIUS))
    height = float(obs[first, 2] - at_grasp[2])
    half = int(np.argmax(dist <= dist[0] / 2))
    low = obs[half, 2] - at_grasp[2] < LOW_HEIGHT
    down_first = bool(dist[0] > DOWN_FIRST_MIN and low)
    return NutTraits(g, turn, near, bool(far), height, height < SLIDE_HEIGHT, down_first, still)

