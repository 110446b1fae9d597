"""Scripted operators: waypoint state machines with a parameterised style.

An operator drives a batch of environments from their observations. Each episode walks
through the task's phases (approach, grasp, lift, carry, place, ...); a phase gives a target
end-effector position, yaw and gripper command and says when it is done. The style sets how
the phases are walked: speed, action noise, hesitations (pauses), waypoint jitter that the
feedback later corrects, and the task-specific choices (route, approach side, grasp point and
yaw). Actions are proportional control towards the target, clipped to [-1, 1]. Host-side numpy:
operators serve the C MuJoCo backend, where collection runs.
"""

from __future__ import annotations

import abc
import dataclasses
from typing import Any

import numpy as np

from elicit_jax.sim.env import Task, quat_yaw


@dataclasses.dataclass(frozen=True)
class Style:
    """How an operator moves (task-specific choices live in ``choices``).

    Attributes:
      speed: largest position/rotation action magnitude (0-1].
      gain: proportional gain (action per metre of error, in units of the task's pos_scale).
      noise: standard deviation of Gaussian noise added to the motion actions.
      hesitate_prob: per-step probability of starting a pause.
      hesitate_steps: (low, high) length of a pause in control steps.
      jitter: std (m) of a per-episode offset of the approach waypoints (corrected later).
      tol: distance (m) at which a waypoint counts as reached.
      choices: task-specific style choices (route, grasp point, grasp yaw offset, ...).
    """

    speed: float = 1.0
    gain: float = 1.5
    noise: float = 0.02
    hesitate_prob: float = 0.0
    hesitate_steps: tuple[int, int] = (3, 8)
    jitter: float = 0.0
    tol: float = 0.01
    choices: tuple[tuple[str, Any], ...] = ()

    def choice(self, key: str, default: Any) -> Any:
        """A task-specific choice by name."""
        return dict(self.choices).get(key, default)

    def paused(self, phases: tuple[int, ...], steps: int) -> Style:
        """This style holding still ``steps`` control steps on entering each of ``phases``
        (the ``pause_at`` and ``pause_steps`` choices; see
        :meth:`Operator.pause_at_phase_starts`)."""
        pause = (("pause_at", phases), ("pause_steps", steps))
        return dataclasses.replace(self, choices=(*self.choices, *pause))


@dataclasses.dataclass
class Targets:
    """Per-environment targets of the current phase (B environments).

    Attributes:
      pos: (B, 3) target end-effector position.
      yaw: (B,) target end-effector yaw.
      grip: (B,) gripper command (-1 open, +1 closed).
      done: (B,) bool, the phase's exit condition holds.
    """

    pos: np.ndarray
    yaw: np.ndarray
    grip: np.ndarray
    done: np.ndarray


class Operator(abc.ABC):
    """A scripted operator for one task; subclasses define :meth:`targets` per phase."""

    n_phases: int = 1

    def __init__(self, task: Task, style: Style, name: str) -> None:
        self.task = task
        self.style = style
        self.name = name
        self.phase = np.zeros(0, np.int64)

    def reset(self, obs: np.ndarray, rng: np.random.Generator) -> None:
        """Start B new episodes from their first observations ``obs (B, 23)``."""
        b = len(obs)
        self.rng = rng
        self.phase = np.zeros(b, np.int64)
        self.phase_steps = np.zeros(b, np.int64)
        self.pause = np.zeros(b, np.int64)
        self.jitter = rng.normal(0.0, self.style.jitter, (b, 3)) * np.array([1.0, 1.0, 0.3])
        self.start_obs = np.array(obs, np.float64)
        self.setup(obs)

    def setup(self, obs: np.ndarray) -> None:  # noqa: B027  (optional hook)
        """Per-episode choices drawn at reset (override)."""

    @abc.abstractmethod
    def targets(self, obs: np.ndarray) -> Targets:
        """Targets of each environment's current phase."""

    def pause_at_phase_starts(self) -> None:
        """Hold still for ``pause_steps`` control steps on entering a phase listed in the
        style's ``pause_at`` choice (the gripper command is kept; see :meth:`act`)."""
        phases = self.style.choice("pause_at", NO_PAUSE["pause_at"])
        if not phases:
            return
        start = np.isin(self.phase, phases) & (self.phase_steps == 0)
        self.pause[start] = self.style.choice("pause_steps", NO_PAUSE["pause_steps"])

    def hover_phase(
        self, phase: int, eef: np.ndarray, hover: np.ndarray, aligned: np.ndarray,
        pos: np.ndarray, done: np.ndarray,
    ) -> None:  # fmt: skip
        """Phase ``phase``, the hover above a grasp: towards ``hover (B, 3)``; done once
        within the style's ``tol`` of it in the table plane and 15 mm in height, with the
        wrist ``aligned (B,)``. Fills ``pos`` and ``done`` (B, ...) in place."""
        m = self.phase == phase
        pos[m] = hover[m]
        xy_err = np.linalg.norm(eef[:, :2] - hover[:, :2], axis=1)
        z_err = np.abs(eef[:, 2] - hover[:, 2])
        done |= m & (xy_err < self.style.tol) & aligned & (z_err < 0.015)

    def restart_if_dropped(
        self,
        obs: np.ndarray,
        targets: tuple[np.ndarray, np.ndarray, np.ndarray],
        carrying: tuple[int, int],
        restart: int,
        gap: float,
    ) -> None:
        """A correction: restart at phase ``restart`` with the jaw open when, during the
        ``carrying`` phases (first, last), the object (``obs[:, 9:12]``) is more than ``gap``
        below the end effector, i.e. it slipped from the jaw.

        Args:
          targets: the phase targets being built, updated in place: position (B, 3),
            gripper (B,), phase done (B,).
        """
        pos, grip, done = targets
        eef, obj, ph = obs[:, 0:3], obs[:, 9:12], self.phase
        slipped = (ph >= carrying[0]) & (ph <= carrying[1]) & (eef[:, 2] - obj[:, 2] > gap)
        self.phase[slipped] = restart
        self.phase_steps[slipped] = 0
        grip[slipped] = -1.0
        done[slipped] = False
        pos[slipped] = eef[slipped] + np.array([0.0, 0.0, 0.01])

    def yaw_error(self, target: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """(B,) wrist turn still to make towards the target yaw (rad), within the joint's
        range (override where the end effector's frame or range differs)."""
        return np.clip(wrap(target), -YAW_LIMIT, YAW_LIMIT) - quat_yaw(obs[:, 3:7])

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Actions ``(B, 7)`` in [-1, 1] for observations ``obs (B, 23)``."""
        s, cfg = self.style, self.task.config
        tg = self.targets(obs)
        advance = tg.done & (self.phase < self.n_phases - 1)
        self.phase = np.where(advance, self.phase + 1, self.phase)
        self.phase_steps = np.where(advance, 0, self.phase_steps + 1)
        err = tg.pos - obs[:, 0:3]
        move = np.clip(s.gain * err / cfg.pos_scale, -s.speed, s.speed)
        yaw_err = self.yaw_error(tg.yaw, obs)
        turn = np.clip(s.gain * yaw_err / cfg.rot_scale, -s.speed, s.speed)
        act = np.zeros((len(obs), 7))
        act[:, 0:3] = move
        act[:, 5] = turn
        act[:, _NOISY] += self.rng.normal(0.0, s.noise, (len(obs), len(_NOISY)))
        act[:, 6] = tg.grip
        start = (self.pause == 0) & (self.rng.random(len(obs)) < s.hesitate_prob)
        lo, hi = s.hesitate_steps
        self.pause = np.where(start, self.rng.integers(lo, hi + 1, len(obs)), self.pause)
        paused = self.pause > 0
        act[paused, 0:6] = 0.0
        self.pause = np.maximum(self.pause - 1, 0)
        return np.clip(act, -1.0, 1.0)


_NOISY = [0, 1, 2, 5]
NO_PAUSE: dict[str, Any] = {"pause_at": (), "pause_steps": 0}
"""The pause choices of a style that sets none (it never holds still)."""
ALIGN_TOL = 0.08
"""Wrist yaw error (rad) at which a grasp or placing yaw counts as reached (a style may set
the ``align_tol`` choice; simulated people imagine others' demonstrations with a looser one)."""
YAW_LIMIT = 3.07
"""Largest wrist yaw an operator turns to (the joint stops at 3.09 rad, so the observed yaw
equals the joint angle and operators turn within the joint's range, never across pi)."""


def wrap(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (angle + np.pi) % (2 * np.pi) - np.pi


def reached(pos: np.ndarray, target: np.ndarray, tol: float) -> np.ndarray:
    """(B,) bool: ``pos (B, 3)`` within ``tol`` of ``target (B, 3)``."""
    return np.linalg.norm(pos - target, axis=-1) < tol
