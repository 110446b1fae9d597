"""MJX backend: one jitted function rolls out B environments with the policy in the loop.

The environments are ``jax.vmap``-ed over the task's single-environment ``reset_to``/``step``;
the policy acts on the whole batch ``(B, 23)`` once per control step (its ``act`` is batched by
contract). A ``lax.while_loop`` runs the horizon and stops early once every rollout has
succeeded; success is tracked per rollout and frozen at the first success.

On a machine with several devices the environments are split across them along the batch
axis (a ``NamedSharding`` over a 1-D mesh, :mod:`elicit_jax.sharding`): the batch is
padded to a multiple of the device count with copies of its last initial state (a copy
finishes exactly when its original does, so the early stop is unchanged) and trimmed after.
With one device nothing is placed or copied.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.sharding import batch_shardings, devices_for, pad_rows, place
from elicit_jax.sim.env import Task

if TYPE_CHECKING:
    from elicit_jax.policy.base import Policy

EXPORT_FORMAT = 1


@functools.lru_cache(maxsize=8)
def rollout_fn(task: Task, horizon: int) -> Any:
    """The jitted rollout of ``task`` over ``horizon`` control steps.

    Returns:
      ``fn(policy, qpos (B, nq), mocap_pos (B, nmocap, 3))`` -> dict of ``success (B,)``
      bool, ``steps_to_success (B,)`` int32 (``horizon`` when never), ``ret (B,)`` return up to
      the first success, ``final_obs (B, 23)``, ``unstable (B,)`` (non-finite state).
      ``policy`` is a pytree with ``init_carry`` and
      ``act`` (see :mod:`elicit_jax.policy.base`); one compile serves every policy of the same
      architecture.
    """
    import jax
    import jax.numpy as jnp

    def run(policy: Policy, qpos: Any, mocap: Any) -> dict[str, Any]:
        b = qpos.shape[0]
        states = jax.vmap(task.reset_to)(qpos, mocap)
        carry = policy.init_carry(b)
        zeros_i = jnp.full((b,), horizon, jnp.int32)

        def cond(c: tuple) -> Any:
            t, states, _, _, _ = c
            return (t < horizon) & ~jnp.all(states.done)

        def body(c: tuple) -> tuple:
            t, states, carry, steps, ret = c
            carry, action = policy.act(carry, states.obs)
            new = jax.vmap(task.step)(states, action)
            newly = new.done & ~states.done
            steps = jnp.where(newly, t + 1, steps)
            ret = ret + jnp.where(states.done, 0.0, new.reward)
            return t + 1, new, carry, steps, ret

        init = (jnp.zeros((), jnp.int32), states, carry, zeros_i, jnp.zeros((b,)))
        _, states, _, steps, ret = jax.lax.while_loop(cond, body, init)
        unstable = ~jnp.all(jnp.isfinite(states.obs), axis=-1)
        return {
            "success": states.done & ~unstable,
            "steps_to_success": steps,
            "ret": ret,
            "final_obs": states.obs,
            "unstable": unstable,
        }

    return jax.jit(run)


def rollout_mjx(
    task: Task,
    policy: Policy,
    seeds: np.ndarray,
    horizon: int | None = None,
    n_devices: int | None = None,
) -> dict[str, np.ndarray]:
    """Roll out ``policy`` on MJX from the seeded initial states ``seeds (B,)``.

    The rollout is traced once per (task, horizon, architecture, batch, devices) and kept as
    a serialised ``jax.export`` module next to JAX's compilation cache, so a later process
    skips tracing (tens of seconds for MJX) as well as compiling.

    Args:
      task: the task.
      policy: a ``Policy`` pytree.
      seeds: (B,) initial-state seeds.
      horizon: control steps (default: the task's).
      n_devices: devices to split the environments across (default: all that JAX sees; at
        most one per rollout).

    Returns:
      dict of numpy arrays (see :func:`rollout_fn`).
    """
    b = len(np.asarray(seeds))
    out = rollout_mjx_on_devices(task, policy, seeds, horizon, n_devices)
    return {k: np.asarray(v)[:b] for k, v in out.items()}


def rollout_mjx_on_devices(
    task: Task,
    policy: Policy,
    seeds: np.ndarray,
    horizon: int | None = None,
    n_devices: int | None = None,
) -> dict[str, Any]:
    """:func:`rollout_mjx` without the trimming: device arrays of the padded batch.

    Returns:
      dict of arrays ``(B', ...)`` where ``B'`` rounds ``B`` up to a multiple of the devices
      used; with several devices each array is split across them along axis 0.
    """
    import jax

    from elicit_jax.runtime import check_mjx_threads

    check_mjx_threads()
    seeds = np.asarray(seeds)
    devices = devices_for(len(seeds), n_devices)
    pad = (-len(seeds)) % devices
    qpos, mocap = task.init_states(seeds)
    qpos, mocap = pad_rows(qpos.astype(np.float32), pad), pad_rows(mocap.astype(np.float32), pad)
    leaves, treedef = jax.tree.flatten(policy)
    shapes = tuple((tuple(x.shape), str(x.dtype)) for x in leaves)
    h = int(horizon or task.config.horizon)
    fn = exported_rollout(task, h, treedef, shapes, len(qpos), devices)
    if devices > 1:
        rows, replicated = batch_shardings(devices)
        qpos, mocap, leaves = place(qpos, rows), place(mocap, rows), place(leaves, replicated)
    return fn(leaves, qpos, mocap)


def export_dir() -> Path:
    """Where serialised rollout modules live: inside JAX's persistent cache directory."""
    from elicit_jax.runtime import default_cache_dir

    return Path(os.environ.get("JAX_COMPILATION_CACHE_DIR") or default_cache_dir()) / "elicit"


@functools.lru_cache(maxsize=16)
def exported_rollout(
    task: Task, horizon: int, treedef: Any, shapes: tuple, batch: int, devices: int = 1
) -> Callable[..., Any]:
    """``fn(policy_leaves, qpos, mocap_pos)``: the rollout, from the export cache if present.

    With ``devices > 1`` the module is exported for that many devices, the environments
    (``qpos``, ``mocap_pos`` and every output) split along axis 0 and the policy replicated;
    an exported module only runs on the device count it was exported for, so the count (and
    the platform) is part of the cache key.
    """
    import jax
    from jax import export

    from elicit_jax.artifact import library_versions

    ident = repr(
        (EXPORT_FORMAT, task.name, task.xml(), task.config, horizon, str(treedef), shapes,
         batch, devices, jax.default_backend(), sorted(library_versions().items()))
    )  # fmt: skip
    key = hashlib.sha256(ident.encode()).hexdigest()[:24]
    path = export_dir() / f"rollout-{task.name}-{key}.bin"
    exp = None
    if path.exists():
        with contextlib.suppress(ValueError, TypeError, KeyError, IndexError, RuntimeError):
            exp = export.deserialize(bytearray(path.read_bytes()))
    if exp is None:
        run = rollout_fn(task, horizon)

        def flat(leaves: list, qpos: Any, mocap: Any) -> Any:
            return run(jax.tree.unflatten(treedef, leaves), qpos, mocap)

        rows = replicated = None
        jitted = jax.jit(flat)
        if devices > 1:
            rows, replicated = batch_shardings(devices)
            shardings = (replicated, rows, rows)
            jitted = jax.jit(flat, in_shardings=shardings, out_shardings=rows)
        specs = [jax.ShapeDtypeStruct(s, d, sharding=replicated) for s, d in shapes]
        qspec = jax.ShapeDtypeStruct((batch, task.nq), np.float32, sharding=rows)
        mspec = jax.ShapeDtypeStruct((batch, task.nmocap, 3), np.float32, sharding=rows)
        exp = export.export(jitted)(specs, qspec, mspec)
        with contextlib.suppress(OSError):
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_bytes(exp.serialize())
            os.replace(tmp, path)
    return jax.jit(exp.call)


def trajectory_fn(task: Task) -> Any:
    """Jitted open-loop replay: ``fn(qpos (B, nq), mocap (B, nmocap, 3), actions (B, T, 7))``
    -> observations ``(B, T + 1, 23)``, the first being the reset observation."""
    import jax
    import jax.numpy as jnp

    def run(qpos: Any, mocap: Any, actions: Any) -> Any:
        states = jax.vmap(task.reset_to)(qpos, mocap)

        def body(s: Any, a: Any) -> tuple:
            s = jax.vmap(task.step)(s, a)
            return s, s.obs

        _, obs = jax.lax.scan(body, states, jnp.swapaxes(actions, 0, 1))
        return jnp.concatenate([states.obs[:, None], jnp.swapaxes(obs, 0, 1)], axis=1)

    return jax.jit(run)
