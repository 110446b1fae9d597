"""What a robosuite nut demonstration did, measured from its own states and actions.

A study that calls an operator *conflicting* relies on its demos actually doing the thing that
conflicts with the base operator's. That is measured here per episode from the recorded
observations and actions alone: no operator, style or seed is consulted, so the same
measurement applies to imported human demonstrations.

Robosuite's low-dimensional observation: end effector at ``obs[0:3]``, its x-y-z-w quaternion
at ``obs[3:7]``, the nut at ``obs[16:19]``, its quaternion at ``obs[19:23]``. Positions are read
in the nut's frame (end effector minus nut in the table plane), heights above the nut's resting
height (its median height until the jaw closes), so a nut nudged on the way, or tipped where
the jaw closes, does not change what is measured. The grasp position is where the jaw first
closes. Four traits:

- **grasp side**: the jaw is symmetric, so the handle can be taken at two wrist yaws half a
  turn apart. The *near* side is the one reachable with at most a quarter turn from the start
  pose; a demo grasps on the **far** side when the wrist turn it made by the moment the jaw
  closes differs from the near turn by more than a quarter turn.
- **approach height**: the end effector's height above the nut when it first came within
  ``APPROACH_RADIUS`` of its grasp position; under ``SLIDE_HEIGHT`` it slid in along the handle
  (``slide_in``: ``mild`` comes down beside the handle's tip and slides the last 6 cm).
- **down first**: the share of its table-plane path to the grasp that the end effector
  travelled less than ``LOW_HEIGHT`` above the nut (``low_share``); over ``LOW_SHARE`` it came
  down first, then went across. The base goes across about 6 cm above the nut and comes down
  over the handle: across, then down (the shares measured for each operator are in
  docs/operators.md).
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
LOW_HEIGHT = 0.045
"""Height (m) above the grasp position under which the way across counts as low."""
LOW_SHARE = 0.5
"""Share of the table-plane path to the grasp travelled low above which a demo came down first."""
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
      low_share: share of the table-plane path to the grasp travelled low (NaN when the jaw
        never closes).
      down_first: ``low_share`` is over ``LOW_SHARE`` (module docstring).
      still_start: leading control steps with no motion command.
    """

    grasp_step: int
    grasp_turn: float
    near_turn: float
    far_grasp: bool
    approach_height: float
    slide_in: bool
    low_share: float
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
        nan = float("nan")
        return NutTraits(-1, nan, near, False, nan, False, nan, False, still)
    g = int(closing[0])
    turn = float(yaw[g] - start)
    far = abs(turn - near) > np.pi / 2
    # in the nut's frame: a nut nudged on the way does not move the path; heights above the
    # nut's resting height (the jaw may close a little above it, on a nut it tipped)
    rel = obs[: g + 1, 0:2] - obs[: g + 1, 16:18]
    above = obs[: g + 1, 2] - float(np.median(obs[: g + 1, 18]))
    dist = np.linalg.norm(rel - rel[-1], axis=1)
    first = int(np.argmax(dist < APPROACH_RADIUS))
    height = float(above[first])
    steps = np.linalg.norm(np.diff(rel, axis=0), axis=1)
    low = above[1:] < LOW_HEIGHT
    share = float((steps * low).sum() / steps.sum()) if steps.sum() > 0 else 0.0
    return NutTraits(
        g, turn, near, bool(far), height, height < SLIDE_HEIGHT, share, share > LOW_SHARE, still
    )
