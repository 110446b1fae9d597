"""One environment of any task in this process: for sessions, replays and the browser's scene.

A session steps one environment at a time and reads its MuJoCo state (joint positions to
record, body poses to draw), so it needs the environment in its own process.
:func:`open_env` returns one with :class:`~elicit_jax.sim.rollout_mujoco.BatchSim`'s interface
for a batch of one (``reset_seeds``, ``step``, ``obs``, ``success``, ``unstable``, ``model``,
``datas``, ``close``): a C MuJoCo ``BatchSim`` for this project's tasks, a
:class:`RobosuiteEnv` for a robosuite task.

robosuite environments take seconds to build, so a closed :class:`RobosuiteEnv` goes back to
an idle list of its spec and the next :func:`open_env` of that spec takes it (a server's
later operators, a test module's sessions); every episode starts with a seeded reset, so a
reused environment starts exactly as a fresh one. robosuite draws its initial state from
NumPy's global generator: resets are serialised by a lock (sessions run on several threads
of a server) and the generator's state is put back afterwards, so a session does not disturb
other users of ``np.random`` in the process.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

_LOCK = threading.Lock()
_IDLE: dict[Any, list[Any]] = {}
ROBOSUITE_HORIZON = 1_000_000
"""Horizon robosuite is built with: its own clock never ends an episode; the session counts."""


def open_env(task: Any) -> Any:
    """One environment of ``task`` in this process (see the module docstring)."""
    if getattr(task, "backend", "") == "robosuite":
        return RobosuiteEnv.acquire(task.spec)
    from elicit_jax.sim.rollout_mujoco import BatchSim

    return BatchSim(task, 1, threads=1)


def control_period(task: Any) -> float:
    """Seconds per control step of ``task`` (a robosuite task: 1 / its control rate)."""
    c = task.config
    freq = getattr(c, "control_freq", None)
    return 1.0 / float(freq) if freq else float(c.substeps * c.timestep)


def robosuite_model(spec: Any) -> Any:
    """The MuJoCo ``MjModel`` of robosuite environments of ``spec`` (builds one, kept idle,
    when none exists in this process yet; read it, never change it)."""
    env = RobosuiteEnv.acquire(spec)
    model = env.model
    env.close()
    return model


class RobosuiteEnv:
    """One robosuite environment in this process, as a batch of one.

    Attributes:
      obs: (1, D) current observation (the spec's keys, concatenated).
      success: (1,) robosuite's success check of the current state.
      unstable: (1,) the simulation failed (an exception or a non-finite observation); the
        environment is then frozen and never counts as a success.
      model, datas: the raw MuJoCo ``MjModel`` and ``[MjData]`` (read them, never write).
    """

    def __init__(self, spec: Any) -> None:
        import logging

        from elicit_jax.sim import robosuite_env as rs

        rs.import_robosuite()
        logging.getLogger("robosuite_logs").setLevel(logging.ERROR)  # its chatter, not ours
        self.spec = spec
        self.batch = 1
        with _LOCK:  # building resets the environment too: from NumPy's global generator
            state = np.random.get_state()
            try:
                self.env = rs.make_env(spec, ROBOSUITE_HORIZON)
            finally:
                np.random.set_state(state)
        self.model = self.env.sim.model._model
        self.obs = np.zeros((1, 0))
        self.success = np.zeros(1, bool)
        self.unstable = np.zeros(1, bool)
        self._open = True
        self.reset_seeds(np.array([0]))

    @classmethod
    def acquire(cls, spec: Any) -> RobosuiteEnv:
        """An idle environment of ``spec``, or a new one."""
        with _LOCK:
            idle = _IDLE.get(spec)
            env = idle.pop() if idle else None
        if env is None:
            return cls(spec)
        env._open = True
        return env

    @property
    def datas(self) -> list[Any]:
        return [self.env.sim.data._data]

    def _observe(self, d: dict[str, Any]) -> np.ndarray:
        from elicit_jax.sim import robosuite_env as rs

        obs = rs.flat_obs(d, self.spec.obs_keys)[None]
        if not np.all(np.isfinite(obs)):
            self.unstable[:] = True
        else:
            self.obs = obs
        self.success[:] = rs.success(self.env) and not self.unstable[0]
        return self.obs

    def reset_seeds(self, seeds: np.ndarray) -> np.ndarray:
        """Reset to the initial state of ``seeds[0]`` (as the worker processes do)."""
        from elicit_jax.sim import robosuite_env as rs

        with _LOCK:
            state = np.random.get_state()
            try:
                d = rs.reset_seeded(self.env, int(np.asarray(seeds)[0]))
            finally:
                np.random.set_state(state)
        self.unstable[:] = False
        return self._observe(d)

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """Apply ``actions (1, 7)`` for one control step (nothing when frozen or inactive)."""
        if self.unstable[0] or (active is not None and not bool(np.asarray(active)[0])):
            return self.obs
        try:
            d, *_ = self.env.step(np.asarray(actions, np.float64)[0])
        except Exception:  # a diverged simulation: the episode fails, the process lives
            self.unstable[:] = True
            self.success[:] = False
            return self.obs
        return self._observe(d)

    def close(self) -> None:
        """Give the environment back to the idle list of its spec (it stays built)."""
        if self._open:
            self._open = False
            with _LOCK:
                _IDLE.setdefault(self.spec, []).append(self)

    def __enter__(self) -> RobosuiteEnv:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
