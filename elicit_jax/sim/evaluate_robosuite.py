"""Evaluation on robosuite: a task's environment, or the one a robomimic file was recorded in.

``evaluate --task robosuite-square`` rolls every policy out in the task's environment;
``evaluate --env-from data.hdf5`` in the environment the file's ``env_args`` name (robosuite
environment, robots, controller, control rate), reading the observation keys the policy was
trained on. Before any rollout the keys and sizes are checked three ways: the file's
``obs/<key>`` widths, the environment's observables and the policy's input size; any
difference is one error line naming the keys. One pool of worker processes (one environment
each) serves every policy, and every policy starts from the same seeded initial states.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.errors import ElicitError
from elicit_jax.sim.robosuite_env import RobosuiteSpec, spec_from_env_args

if TYPE_CHECKING:
    from elicit_jax.policy.base import Policy


def file_obs_dims(path: str | Path) -> tuple[dict[str, Any], dict[str, int]]:
    """A robomimic file's ``env_args`` and its observation widths (from its first demo).

    Raises:
      ElicitError: not a robomimic file, no ``env_args``, or no demos.
    """
    from elicit_jax.data.robomimic import demo_names, env_args, open_hdf5

    with open_hdf5(path) as f:
        args = env_args(f, path)
        if not args or "env_name" not in args:
            raise ElicitError("data.attrs['env_args'] names no environment", path)
        first = demo_names(f, path)[0]
        obs = f["data"][first].get("obs")
        if obs is None:
            raise ElicitError(f"data/{first} has no obs group", path)
        dims = {k: int(np.prod(obs[k].shape[1:])) for k in obs}
    return args, dims


def key_differences(
    keys: Sequence[str], file_dims: dict[str, int], env_dims: dict[str, int], env_name: str
) -> list[str]:
    """Each of the policy's observation keys whose size differs between file and env."""
    out = []
    for k in keys:
        a, b = file_dims.get(k), env_dims.get(k)
        if a != b:
            left = "missing" if a is None else str(a)
            right = "missing" if b is None else str(b)
            out.append(f"{k} (file {left}, {env_name} {right})")
    return out


def check_obs(
    path: str | Path,
    keys: Sequence[str],
    obs_dim: int,
    file_dims: dict[str, int],
    env_dims: dict[str, int],
    env_name: str,
) -> None:
    """Raise one line when the policy's observation cannot be read from the environment."""
    if not keys:
        raise ElicitError(
            "the policy records no observation keys (train it on imported robomimic demos)",
            path,
        )
    diff = key_differences(keys, file_dims, env_dims, env_name)
    if diff:
        raise ElicitError(f"observation keys differ: {'; '.join(diff)}", path)
    total = sum(file_dims[k] for k in keys)
    if total != obs_dim:
        raise ElicitError(
            f"the policy reads {obs_dim} values but keys {', '.join(keys)} hold {total}", path
        )


def evaluate_refs_robosuite(
    refs: Sequence[Any],
    config: Any,
    seeds: np.ndarray,
    progress: Callable[[Any, float], None] | None = None,
    record_states: bool = False,
    action_noise: float = 0.0,
) -> tuple[list[tuple[Any, dict]], int, dict[str, Any]]:
    """Roll out every policy reference on robosuite workers (``record_states`` and
    ``action_noise``: see :func:`elicit_jax.sim.rollout_robosuite.rollout_policy`).

    Returns:
      ``[(ref, outcome)]``, the horizon and timing (``policy_seconds``, ``env_steps``,
      ``seconds``).
    """
    import time

    from elicit_jax.policy.base import jitted_act
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.runtime import available_cpus
    from elicit_jax.sim.rollout_robosuite import rollout_policy, shared_pool

    policies = []
    for ref in refs:
        policies.append(load_policy(ref.path, ref.checkpoint).policy)
    spec, horizon, file_dims = _spec(config, policies[0])
    workers = min(config.workers or available_cpus(), len(seeds))
    results, timing = [], {"policy_seconds": 0.0, "env_steps": 0, "seconds": 0.0}
    t0 = time.perf_counter()
    pool = shared_pool(spec, workers)
    for ref, policy in zip(refs, policies, strict=True):
        _check_policy(config, ref, policy, spec, pool, file_dims)
        out = rollout_policy(spec, jitted_act(), policy, seeds, horizon, workers, pool,
                             record_states, action_noise)  # fmt: skip
        timing["policy_seconds"] += float(out.pop("policy_seconds"))
        timing["env_steps"] += int(out.pop("env_steps"))
        results.append((ref, out))
        if progress is not None:
            progress(ref, float(np.mean(out["success"])))
    timing["seconds"] = time.perf_counter() - t0
    return results, horizon, timing


def _spec(config: Any, policy: Policy) -> tuple[RobosuiteSpec, int, dict[str, int] | None]:
    """The environment to evaluate in, its horizon and (for ``--env-from``) the file's
    observation widths."""
    from elicit_jax.sim.env import make_task

    if config.env_from:
        args, dims = file_obs_dims(config.env_from)
        keys = tuple(policy.obs_fields)
        horizon = config.horizon or int(args.get("env_kwargs", {}).get("horizon") or 500)
        return spec_from_env_args(args, keys), horizon, dims
    task = make_task(config.task)
    return task.spec, config.horizon or task.config.horizon, None


def _check_policy(
    config: Any, ref: Any, policy: Policy, spec: RobosuiteSpec, pool: Any, file_dims: Any
) -> None:
    if policy.action_dim != 7:
        raise ElicitError(f"policy has action_dim={policy.action_dim}; robosuite needs 7", ref.path)
    if file_dims is not None:
        check_obs(config.env_from, tuple(policy.obs_fields), policy.obs_dim, file_dims,
                  pool.obs_dims, spec.env_name)  # fmt: skip
        if tuple(policy.obs_fields) != spec.obs_keys:
            raise ElicitError(
                f"policies read different observation keys ({list(policy.obs_fields)} vs "
                f"{list(spec.obs_keys)}): evaluate them separately", ref.path
            )  # fmt: skip
    elif policy.obs_dim != pool.obs_dim:
        raise ElicitError(
            f"policy has obs_dim={policy.obs_dim}; task '{config.task}' gives {pool.obs_dim}",
            ref.path,
        )
