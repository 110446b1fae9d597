"""C MuJoCo backend: a batch of environments stepped by a thread pool.

:class:`BatchSim` runs B copies of a task on C MuJoCo. Each control step takes the whole
batch's actions ``(B, 7)`` (one batched policy call upstream), sets the actuator targets with
the task's shared kernel, and advances each environment ``substeps`` physics steps. The
environments are split into one contiguous chunk per thread; ``mj_step`` releases the GIL, so
chunks run in parallel. Observations and success come from the same sensor and success
kernels as the MJX backend.
"""

from __future__ import annotations

import itertools
import os
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from elicit_jax.sim.env import N_GRIPPER_Q, Task


def default_threads() -> int:
    """Worker threads for C MuJoCo stepping: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


class BatchSim:
    """B environments of one task on C MuJoCo.

    Attributes:
      obs: (B, 23) current observations.
      success: (B,) bool success in the current state.
      unstable: (B,) bool, the physics diverged (MuJoCo then resets the data); such an
        environment is frozen and never counts as a success.
    """

    def __init__(self, task: Task, batch: int, threads: int | None = None) -> None:
        import mujoco

        self.task = task
        self.batch = int(batch)
        self.model = task.mj_model
        self.datas = [mujoco.MjData(self.model) for _ in range(self.batch)]
        self.threads = min(threads or default_threads(), self.batch)
        bounds = np.linspace(0, self.batch, self.threads + 1).astype(int)
        self._chunks = [(int(a), int(b)) for a, b in itertools.pairwise(bounds) if b > a]
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        self.obs = np.zeros((self.batch, 23))
        self.success = np.zeros(self.batch, bool)
        self.unstable = np.zeros(self.batch, bool)

    def close(self) -> None:
        """Stop the worker threads."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def __enter__(self) -> BatchSim:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def reset(self, qpos: np.ndarray, mocap_pos: np.ndarray) -> np.ndarray:
        """Put every environment at rest at ``qpos (B, nq)``, ``mocap_pos (B, nmocap, 3)``.

        Returns:
          (B, 23) observations.
        """
        import mujoco

        open_action = np.zeros(7)
        open_action[6] = -1.0
        for i, d in enumerate(self.datas):
            mujoco.mj_resetData(self.model, d)
            d.qpos[:] = qpos[i]
            if self.task.nmocap:
                d.mocap_pos[:] = mocap_pos[i]
            d.ctrl[:] = self.task.ctrl_from_action(qpos[i, :N_GRIPPER_Q], open_action)
            mujoco.mj_forward(self.model, d)
        self.unstable[:] = False
        return self._observe()

    def reset_seeds(self, seeds: np.ndarray) -> np.ndarray:
        """Reset to the task's seeded initial states (same sampler as the MJX backend)."""
        qpos, mocap = self.task.init_states(np.asarray(seeds))
        return self.reset(qpos, mocap)

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """Apply ``actions (B, 7)`` for one control step; ``active (B,)`` masks frozen envs.

        Returns:
          (B, 23) observations after the step.
        """
        qpos = np.stack([d.qpos[:N_GRIPPER_Q] for d in self.datas])
        ctrl = self.task.ctrl_from_action(qpos, np.asarray(actions, np.float64))
        for d, c in zip(self.datas, ctrl, strict=True):
            d.ctrl[:] = c
        mask = np.ones(self.batch, bool) if active is None else np.asarray(active, bool)
        mask = mask & ~self.unstable
        if self._pool is None:
            self._run(0, self.batch, mask)
        else:
            futures = [self._pool.submit(self._run, a, b, mask) for a, b in self._chunks]
            for f in futures:
                f.result()
        return self._observe()

    def _run(self, start: int, stop: int, mask: np.ndarray) -> None:
        import mujoco

        n = self.task.config.substeps
        w = mujoco.mjtWarning
        bad = [int(k) for k in (w.mjWARN_BADQPOS, w.mjWARN_BADQVEL, w.mjWARN_BADQACC)]
        for i in range(start, stop):
            if mask[i]:
                d = self.datas[i]
                before = sum(d.warning[k].number for k in bad)
                mujoco.mj_step(self.model, d, n)
                if sum(d.warning[k].number for k in bad) != before:
                    self.unstable[i] = True

    def _observe(self) -> np.ndarray:
        sd = np.stack([d.sensordata for d in self.datas])
        self.obs = self.task.obs_from_sensordata(sd)
        self.success = np.asarray(self.task.success_from_obs(self.obs), bool) & ~self.unstable
        return self.obs

    def qpos(self) -> np.ndarray:
        """(B, nq) joint positions."""
        return np.stack([d.qpos.copy() for d in self.datas])


def rollout_policy(
    task: Task,
    act: Any,
    policy: Any,
    seeds: np.ndarray,
    horizon: int,
    threads: int | None = None,
    groups: int = 2,
) -> dict[str, np.ndarray]:
    """Roll a policy out on C MuJoCo from seeded initial states, policy and physics overlapped.

    The environments are split into ``groups`` (2 by default when there are at least 8): while
    one group's batched policy call runs (JAX dispatches it asynchronously), the physics of
    the other group steps in the thread pool, so neither the policy nor the stepping leaves
    the cores idle. Every environment still gets one policy action per control step.

    Args:
      act: jitted ``act(policy, carry, obs (b, 23)) -> (carry, action (b, 7))``.
      seeds: (B,) initial-state seeds.
      horizon: control steps.

    Returns:
      dict of ``success (B,)``, ``steps_to_success (B,)`` (horizon when never), ``ret (B,)``,
      ``final_obs (B, 23)``, ``unstable (B,)`` (the physics diverged; frozen, not a success).
    """
    seeds = np.asarray(seeds)
    n = len(seeds)
    parts = [p for p in np.array_split(np.arange(n), groups if n >= 8 else 1) if len(p)]
    sims = [BatchSim(task, len(p), threads) for p in parts]
    try:
        obs = [sim.reset_seeds(seeds[p]) for sim, p in zip(sims, parts, strict=True)]
        carry = [policy.init_carry(len(p)) for p in parts]
        done = [sim.success.copy() for sim in sims]
        steps = [np.full(len(p), horizon, np.int32) for p in parts]
        pending: list[Any] = [None] * len(parts)

        def dispatch(g: int) -> None:
            if not done[g].all():
                carry[g], pending[g] = act(policy, carry[g], obs[g].astype(np.float32))

        def advance(g: int, t: int) -> None:
            if pending[g] is None:
                return
            action = np.asarray(pending[g], np.float64)
            pending[g] = None
            obs[g] = sims[g].step(action, active=~done[g])
            newly = sims[g].success & ~done[g]
            steps[g][newly] = t + 1
            done[g] |= sims[g].success

        for t in range(horizon):
            if all(d.all() for d in done):
                break
            if t == 0:
                for g in range(len(parts)):
                    dispatch(g)
            for g in range(len(parts)):
                advance(g, t)
                if t + 1 < horizon:
                    dispatch(g)
        out = {
            "success": np.concatenate(done),
            "steps_to_success": np.concatenate(steps),
            "final_obs": np.concatenate(obs),
            "unstable": np.concatenate([sim.unstable.copy() for sim in sims]),
        }
        out["ret"] = out["success"].astype(np.float64)
        return out
    finally:
        for sim in sims:
            sim.close()
