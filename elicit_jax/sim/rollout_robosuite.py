"""robosuite backend: worker processes, one environment each, stepped in lock-step.

robosuite's step is Python (its controllers run every physics substep), so threads do not
help; processes do. :class:`EnvPool` starts ``workers`` processes (``spawn``: the parent runs
JAX, which must not be forked); each builds one environment of a :class:`RobosuiteSpec` and
answers reset/step requests over a pipe. The parent sends every running environment its action,
then collects every answer, so the environments step in parallel while the policy (or a
scripted operator) is called once per control step for the whole batch, as on the other
backends.

:func:`rollout_policy` keeps every worker busy: when a rollout ends (success or horizon) its
worker starts the next initial state, for feed-forward policies; a recurrent policy's carry
is shared by its batch, so it runs waves of ``workers`` rollouts instead. Each rollout starts
from its seed's initial state (:func:`elicit_jax.sim.robosuite_env.reset_seeded`), whichever
worker runs it, so every policy sees the same initial states.
"""

from __future__ import annotations

import atexit
import contextlib
import multiprocessing as mp
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.errors import ElicitError
from elicit_jax.sim.robosuite_env import RobosuiteSpec

if TYPE_CHECKING:
    from elicit_jax.policy.base import Policy


def _worker(conn: Any, spec: RobosuiteSpec, horizon: int, fast: bool = True) -> None:
    """Worker loop: build one environment (``fast``: see
    :func:`~elicit_jax.sim.robosuite_env.make_env`), answer ``(cmd, arg)`` requests until
    ``close``."""
    import logging

    from elicit_jax.sim import robosuite_env as rs

    try:
        rs.import_robosuite()
        logging.getLogger("robosuite_logs").setLevel(logging.ERROR)  # its chatter, not ours
        env = rs.make_env(spec, horizon, fast)
        obs = rs.reset_seeded(env, 0)
        conn.send(("ok", rs.obs_dims(obs)))
    except Exception as e:  # report any failure to build to the parent, then stop
        conn.send(("error", f"{type(e).__name__}: {e}"))
        return
    while True:
        cmd, arg = conn.recv()
        if cmd == "close":
            env.close()
            return
        try:
            if cmd == "reset":
                d = rs.reset_seeded(env, arg)
            else:
                d, *_ = env.step(np.asarray(arg, np.float64))
            obs = rs.flat_obs(d, spec.obs_keys)
            conn.send(("ok", (obs, rs.success(env), bool(np.all(np.isfinite(obs))))))
        except Exception as e:  # a diverged simulation: the rollout fails, the worker lives
            conn.send(("ok", (None, False, False)))
            logging.getLogger("elicit_jax.sim.robosuite").info("step failed: %s", e)


class EnvPool:
    """``workers`` robosuite environments in their own processes.

    Attributes:
      obs_dims: size of each observation the environment offers (robomimic names).

    ``fast=False`` builds the environments exactly as robosuite does, without the speed-up of
    :func:`~elicit_jax.sim.robosuite_env.make_env` (``benchmarks/bench_eval_cost.py``
    compares the two).
    """

    def __init__(self, spec: RobosuiteSpec, workers: int, horizon: int, fast: bool = True) -> None:
        ctx = mp.get_context("spawn")
        self.spec = spec
        self.size = int(workers)
        self._conns, self._procs = [], []
        for _ in range(self.size):
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, spec, horizon, fast), daemon=True)
            proc.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(proc)
        answers = [self._recv(i) for i in range(self.size)]
        self.obs_dims: dict[str, int] = answers[0]
        self.obs_dim = sum(self.obs_dims.get(k, 0) for k in spec.obs_keys)

    def _recv(self, i: int) -> Any:
        try:
            status, payload = self._conns[i].recv()
        except EOFError as e:
            self.close()
            raise ElicitError(f"robosuite worker {i} for {self.spec.env_name} died") from e
        if status != "ok":
            self.close()
            raise ElicitError(f"robosuite cannot build {self.spec.env_name}: {payload}")
        return payload

    def request(self, items: Sequence[tuple[int, str, Any]]) -> list[Any]:
        """Send ``(worker, cmd, arg)`` requests, then wait for every answer, in order:
        ``(obs, success, finite)`` per request. Interrupted half-way, the pool closes (its
        pipes would be out of step)."""
        try:
            for i, cmd, arg in items:
                self._conns[i].send((cmd, arg))
            return [self._recv(i) for i, _, _ in items]
        except BaseException:
            self.close()
            raise

    @property
    def alive(self) -> bool:
        """Every worker is running."""
        return bool(self._procs) and all(p.is_alive() for p in self._procs)

    def close(self) -> None:
        """Stop the workers."""
        for conn, proc in zip(self._conns, self._procs, strict=True):
            if proc.is_alive():
                with contextlib.suppress(BrokenPipeError, OSError):
                    conn.send(("close", None))
        for proc in self._procs:
            proc.join(timeout=5)
            if proc.is_alive():
                proc.kill()
                proc.join()
        self._conns, self._procs = [], []

    def __enter__(self) -> EnvPool:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


SHARED_HORIZON = 1_000_000
"""Horizon the shared pools' environments are built with: episodes never end on robosuite's
clock (``ignore_done``); the callers count steps."""
_SHARED: dict[tuple[RobosuiteSpec, int], EnvPool] = {}


def shared_pool(spec: RobosuiteSpec, workers: int) -> EnvPool:
    """A pool of ``workers`` environments of ``spec`` kept for the rest of the process.

    Building robosuite environments takes seconds per worker, so later collections and
    evaluations in the same process (several policies, a pipeline's stages, a test module)
    reuse it; every rollout resets its environment to a seeded initial state, so a reused
    environment starts exactly as a fresh one. The pools close when the process exits.
    """
    key = (spec, int(workers))
    pool = _SHARED.get(key)
    if pool is None or not pool.alive:
        if not _SHARED:
            atexit.register(close_shared)
        pool = _SHARED[key] = EnvPool(spec, workers, SHARED_HORIZON)
    return pool


def close_shared() -> None:
    """Close every shared pool."""
    while _SHARED:
        _SHARED.popitem()[1].close()


class PoolBatch:
    """A batch of B = pool size environments with :class:`~elicit_jax.sim.rollout_mujoco.BatchSim`'s
    interface (``reset_seeds``, ``step``, ``obs``, ``success``, ``unstable``), for collection."""

    def __init__(self, pool: EnvPool) -> None:
        self.pool = pool
        self.batch = pool.size
        self.obs = np.zeros((self.batch, pool.obs_dim))
        self.success = np.zeros(self.batch, bool)
        self.unstable = np.zeros(self.batch, bool)

    def _take(self, idx: Sequence[int], answers: list[Any]) -> np.ndarray:
        for i, (obs, ok, finite) in zip(idx, answers, strict=True):
            if not finite or obs is None:
                self.unstable[i] = True
            else:
                self.obs[i] = obs
            self.success[i] = ok and not self.unstable[i]
        return self.obs.copy()

    def reset_seeds(self, seeds: np.ndarray) -> np.ndarray:
        """Reset environment i to the initial state of ``seeds[i]``."""
        if len(seeds) != self.batch:
            raise ElicitError(f"{len(seeds)} seeds for {self.batch} robosuite workers")
        self.unstable[:] = False
        idx = list(range(self.batch))
        return self._take(idx, self.pool.request([(i, "reset", int(s)) for i, s in
                                                  zip(idx, seeds, strict=True)]))  # fmt: skip

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """Step the active environments (all by default) with ``actions (B, 7)``."""
        mask = np.ones(self.batch, bool) if active is None else np.asarray(active, bool)
        idx = [i for i in range(self.batch) if mask[i] and not self.unstable[i]]
        answers = self.pool.request([(i, "step", actions[i]) for i in idx])
        return self._take(idx, answers)


def rollout_policy(
    spec: RobosuiteSpec,
    act: Any,
    policy: Policy,
    seeds: np.ndarray,
    horizon: int,
    workers: int,
    pool: EnvPool | None = None,
    record_states: bool = False,
    action_noise: float = 0.0,
) -> dict[str, np.ndarray]:
    """Roll ``policy`` out from the initial states of ``seeds`` on robosuite workers.

    Args:
      act: jitted ``act(policy, carry, obs (B, D)) -> (carry, action (B, 7))``.
      workers: worker processes (one environment each), unless ``pool`` is given.
      pool: an open :class:`EnvPool` to use (left open).
      record_states: also return the states the policy acted in and the actions taken.
      action_noise: std of Gaussian exploration noise added to every action (0: none), drawn
        from a generator seeded by the rollout's initial-state seed (as on C MuJoCo), so a
        rollout's noise does not depend on which worker runs it.

    Returns:
      dict of ``success (N,)``, ``steps_to_success (N,)`` (horizon when never), ``ret (N,)``,
      ``unstable (N,)`` (the simulation failed; not a success), ``init_obs (N, D)`` (each
      rollout's first observation), ``policy_seconds`` (time in policy calls) and
      ``env_steps``; with ``record_states`` also ``states (N, horizon, D)`` float32,
      ``state_mask (N, horizon)`` and ``actions (N, horizon, 7)`` (noise included).
    """
    import time

    import jax

    seeds = np.asarray(seeds)
    own = pool is None
    pool = pool or EnvPool(spec, min(workers, len(seeds)), horizon)
    w = pool.size
    slots = _Slots(len(seeds), w, pool.obs_dim, horizon, record_states)
    rngs = [np.random.default_rng(int(s)) for s in seeds] if action_noise > 0 else []
    stateless = not jax.tree.leaves(policy.init_carry(1))
    policy_s, env_steps = 0.0, 0
    try:
        while slots.next < len(seeds) or slots.busy.any():
            if not slots.busy.any() or stateless:
                slots.start(pool, seeds)
                carry = policy.init_carry(w)
                if not slots.busy.any():
                    continue
            t0 = time.perf_counter()
            carry, action = act(policy, carry, slots.obs)
            action = np.asarray(action, np.float64)
            policy_s += time.perf_counter() - t0
            run = [i for i in range(w) if slots.busy[i]]
            for i in run if rngs else ():
                action[i] = action[i] + action_noise * rngs[slots.slot[i]].normal(size=7)
            slots.keep(run, action)
            slots.record(run, pool.request([(i, "step", action[i]) for i in run]))
            env_steps += len(run)
    finally:
        if own:
            pool.close()
    out = slots.out
    out["ret"] = out["success"].astype(np.float64)
    return out | {"policy_seconds": np.float64(policy_s), "env_steps": np.int64(env_steps)}


class _Slots:
    """Which rollout each worker runs and for how many steps, and the rollouts' outcomes:
    a worker whose rollout ended (success, instability, horizon) takes the next one."""

    def __init__(
        self, n: int, workers: int, obs_dim: int, horizon: int, record: bool = False
    ) -> None:
        self.out = {
            "success": np.zeros(n, bool),
            "steps_to_success": np.full(n, horizon, np.int32),
            "ret": np.zeros(n),
            "unstable": np.zeros(n, bool),
            "init_obs": np.zeros((n, obs_dim)),
        }
        if record:
            self.out |= {
                "states": np.zeros((n, horizon, obs_dim), np.float32),
                "state_mask": np.zeros((n, horizon), bool),
                "actions": np.zeros((n, horizon, 7), np.float32),
            }
        self.slot = np.full(workers, -1)  # rollout index each worker runs (-1: idle)
        self.t_slot = np.zeros(workers, np.int64)
        self.obs = np.zeros((workers, obs_dim), np.float32)
        self.horizon = horizon
        self.next = 0

    @property
    def busy(self) -> np.ndarray:
        """Workers running a rollout."""
        return self.slot >= 0

    def start(self, pool: EnvPool, seeds: np.ndarray) -> None:
        """Reset every idle worker to the initial state of the next rollout's seed."""
        out, slot = self.out, self.slot
        starts = []
        for i in np.flatnonzero(slot < 0)[: len(seeds) - self.next]:
            slot[i], self.t_slot[i] = self.next, 0
            starts.append((i, "reset", int(seeds[self.next])))
            self.next += 1
        for (i, _, _), (o, ok, _) in zip(starts, pool.request(starts), strict=True):
            if o is None:  # the reset itself failed: an unstable rollout
                out["unstable"][slot[i]], slot[i] = True, -1
                continue
            self.obs[i] = out["init_obs"][slot[i]] = o
            if ok:  # solved at the start: a success in zero steps
                out["success"][slot[i]], out["steps_to_success"][slot[i]] = True, 0
                slot[i] = -1

    def keep(self, run: list[int], action: np.ndarray) -> None:
        """With recording: the state each running worker's policy acted in and its action."""
        if "states" not in self.out:
            return
        for i in run:
            k, t = self.slot[i], self.t_slot[i]
            self.out["states"][k, t] = self.obs[i]
            self.out["state_mask"][k, t] = True
            self.out["actions"][k, t] = action[i]

    def record(self, run: list[int], answers: list[Any]) -> None:
        """Take the workers' answers to one step; free those whose rollout ended."""
        out = self.out
        for i, (o, ok, finite) in zip(run, answers, strict=True):
            k = self.slot[i]
            self.t_slot[i] += 1
            if not finite or o is None:
                out["unstable"][k] = True
            else:
                self.obs[i] = o
            if ok and not out["unstable"][k]:
                out["success"][k], out["steps_to_success"][k] = True, self.t_slot[i]
            if ok or out["unstable"][k] or self.t_slot[i] >= self.horizon:
                self.slot[i] = -1
