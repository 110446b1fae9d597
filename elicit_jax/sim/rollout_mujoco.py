"""C MuJoCo backend: a batch of environments stepped by a thread pool.

:class:`BatchSim` runs B copies of a task on C MuJoCo. Each control step takes the whole
batch's actions ``(B, 7)`` (one batched policy call upstream), sets the actuator targets with
the task's shared kernel, and advances each environment ``substeps`` physics steps. The
environments are split into one contiguous chunk per thread; the calling thread steps the last
chunk itself while pool threads step the others, and ``mj_step`` releases the GIL, so chunks
run in parallel. Each thread also sets its environments' targets and copies their gripper
joints and sensor data into shared buffers, so the per-environment Python runs beside the
other threads' physics instead of in series before and after it. Observations and success
come from the same sensor and success kernels as the MJX backend.

While any :class:`BatchSim` is open, C MuJoCo's warnings (e.g. "Nan, Inf or huge value in
QACC ... The simulation is unstable") go to the ``elicit_jax.sim.mujoco`` logger at INFO
level instead of the terminal and ``MUJOCO_LOG.TXT``: a diverged environment is already
flagged in :attr:`BatchSim.unstable` (and counted as an unstable rollout), so the message
belongs in the log. The CLI entry point decides where that log goes.
"""

from __future__ import annotations

import itertools
import logging
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.runtime import available_cpus
from elicit_jax.sim.env import N_GRIPPER_Q, OBS_DIM, Task

if TYPE_CHECKING:
    from elicit_jax.policy.base import Policy

LOG = logging.getLogger("elicit_jax.sim.mujoco")
_ROUTE_LOCK = threading.Lock()
_route: dict[str, Any] = {"users": 0, "previous": None, "count": 0}


def _log_warning(message: str) -> None:
    _route["count"] += 1
    LOG.info("MuJoCo warning: %s", message)


def route_warnings(on: bool) -> None:
    """Start (``on``) or stop routing C MuJoCo's warnings to :data:`LOG` (reference counted:
    the handler found before the first start is restored when the last user stops)."""
    import mujoco

    with _ROUTE_LOCK:
        if on:
            if _route["users"] == 0:
                _route["previous"] = mujoco.get_mju_user_warning()
                mujoco.set_mju_user_warning(_log_warning)
            _route["users"] += 1
        elif _route["users"] > 0:
            _route["users"] -= 1
            if _route["users"] == 0:
                mujoco.set_mju_user_warning(_route["previous"])
                _route["previous"] = None


def warning_count() -> int:
    """C MuJoCo warnings routed to the log in this process so far."""
    return int(_route["count"])


def _bad_warnings(d: Any) -> int:
    """Count of bad-qpos/qvel/qacc warnings raised on ``d`` (each one reset the data)."""
    import mujoco

    w = mujoco.mjtWarning
    return sum(
        d.warning[int(k)].number for k in (w.mjWARN_BADQPOS, w.mjWARN_BADQVEL, w.mjWARN_BADQACC)
    )


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
        self.threads = min(threads or available_cpus(), self.batch)
        bounds = np.linspace(0, self.batch, self.threads + 1).astype(int)
        self._chunks = [(int(a), int(b)) for a, b in itertools.pairwise(bounds) if b > a]
        self._pool = ThreadPoolExecutor(self.threads - 1) if self.threads > 1 else None
        self._gripper_q = np.zeros((self.batch, N_GRIPPER_Q))
        self._sensordata = np.zeros((self.batch, self.model.nsensordata))
        self.obs = np.zeros((self.batch, OBS_DIM))
        self.success = np.zeros(self.batch, bool)
        self.unstable = np.zeros(self.batch, bool)
        self._routing = True
        route_warnings(True)

    def close(self) -> None:
        """Stop the worker threads and the routing of MuJoCo's warnings."""
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
        if self._routing:
            self._routing = False
            route_warnings(False)

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
            self._record(i, d)
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
        ctrl = self.task.ctrl_from_action(self._gripper_q, np.asarray(actions, np.float64))
        mask = np.ones(self.batch, bool) if active is None else np.asarray(active, bool)
        mask = mask & ~self.unstable
        *others, last = self._chunks
        futures = [self._pool.submit(self._run, a, b, mask, ctrl) for a, b in others]
        try:
            self._run(*last, mask, ctrl)
        finally:
            for f in futures:
                f.result()
        return self._observe()

    def _run(self, start: int, stop: int, mask: np.ndarray, ctrl: np.ndarray) -> None:
        import mujoco

        n = self.task.config.substeps
        late = (n - 0.5) * self.model.opt.timestep
        for i in range(start, stop):
            if mask[i]:
                d = self.datas[i]
                d.ctrl[:] = ctrl[i]
                t0 = d.time
                first = t0 == 0.0
                before = _bad_warnings(d) if first else 0
                mujoco.mj_step(self.model, d, n)
                # MuJoCo resets a diverged env, restarting its clock: reading the clock is cheap,
                # the warning counters are not (~4 us each, GIL held). From t = 0 a reset on the
                # first substep leaves the clock unchanged, so that step reads the counters.
                if d.time < t0 + late or (first and _bad_warnings(d) != before):
                    self.unstable[i] = True
                self._record(i, d)

    def _record(self, i: int, d: Any) -> None:
        """Copy env ``i``'s gripper joints (next targets) and sensor data (observation)."""
        self._gripper_q[i] = d.qpos[:N_GRIPPER_Q]
        self._sensordata[i] = d.sensordata

    def _observe(self) -> np.ndarray:
        self.obs = self.task.obs_from_sensordata(self._sensordata.copy())
        self.success = np.asarray(self.task.success_from_obs(self.obs), bool) & ~self.unstable
        return self.obs

    def qpos(self) -> np.ndarray:
        """(B, nq) joint positions."""
        return np.stack([d.qpos.copy() for d in self.datas])


def rollout_policy(
    task: Task,
    act: Any,
    policy: Policy,
    seeds: np.ndarray,
    horizon: int,
    threads: int | None = None,
    record_states: bool = False,
    action_noise: float = 0.0,
) -> dict[str, np.ndarray]:
    """Roll a policy out on C MuJoCo from seeded initial states: one batched policy call per
    control step for every environment still running, then the physics in the thread pool.

    One call for the whole batch is deliberate: at the paper's size a policy call on CPU is
    bound by streaming the ensemble's weights from memory, so splitting the batch to overlap
    policy and physics made each control step slower (measured: 3.3k vs 4.1k env-steps/s on
    50 square-nut rollouts, 2 cores).

    Args:
      act: jitted ``act(policy, carry, obs (B, 23)) -> (carry, action (B, 7))``.
      seeds: (B,) initial-state seeds.
      horizon: control steps.
      record_states: also return the states the policy acted in and the actions taken.
      action_noise: std of Gaussian exploration noise added to every action (0: none),
        drawn from a generator seeded by the rollout's own initial-state seed, so a rollout
        is the same whatever batch it runs in.

    Returns:
      dict of ``success (B,)``, ``steps_to_success (B,)`` (horizon when never), ``ret (B,)``,
      ``final_obs (B, 23)``, ``unstable (B,)`` (the physics diverged; frozen, not a success);
      with ``record_states`` also ``states (B, horizon, 23)`` float32 and ``state_mask
      (B, horizon)``, true where the rollout was still running (not yet successful, not
      diverged) and the policy acted in that state, and ``actions (B, horizon, 7)`` float32,
      the actions taken there (noise included).
    """
    seeds = np.asarray(seeds)
    b = len(seeds)
    rngs = [np.random.default_rng(int(s)) for s in seeds] if action_noise > 0 else []
    if record_states:
        states = np.zeros((b, horizon, OBS_DIM), np.float32)
        actions = np.zeros((b, horizon, 7), np.float32)
        state_mask = np.zeros((b, horizon), bool)
    with BatchSim(task, b, threads) as sim:
        obs = sim.reset_seeds(seeds)
        carry = policy.init_carry(b)
        done = sim.success.copy()
        steps = np.full(b, horizon, np.int32)
        for t in range(horizon):
            if done.all():
                break
            if record_states:
                states[:, t] = obs
                state_mask[:, t] = ~done & ~sim.unstable
            carry, action = act(policy, carry, obs.astype(np.float32))
            action = np.asarray(action, np.float64)
            if rngs:
                action = action + action_noise * np.stack([r.normal(size=7) for r in rngs])
            if record_states:
                actions[:, t] = action
            obs = sim.step(action, active=~done)
            newly = sim.success & ~done
            steps[newly] = t + 1
            done |= sim.success
        out = {
            "success": done,
            "steps_to_success": steps,
            "ret": done.astype(np.float64),
            "final_obs": obs,
            "unstable": sim.unstable.copy(),
        }
    if record_states:
        out |= {"states": states, "state_mask": state_mask, "actions": actions}
    return out
