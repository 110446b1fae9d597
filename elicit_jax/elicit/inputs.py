"""A session's inputs loaded and checked: the task, the base demonstrations, the policy it
scores with and the operator (:func:`load_inputs`), before anything is written.

:func:`load_session_policy` is also the loader of a watched folder's policy
(:mod:`elicit_jax.elicit.watch`); :func:`task_action_names` names a task's action dimensions
for the session header and the browser page.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from elicit_jax.elicit.config import SessionConfig
from elicit_jax.elicit.live import check_live_policy
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.data.demos import Demos
    from elicit_jax.policy.loaded import LoadedPolicy


def _check_base(config: SessionConfig, task: Any, base: Demos) -> None:
    """Refuse base demonstrations whose sizes or observation fields are not the task's."""
    from elicit_jax.sim.registry import task_entry

    sizes = task_entry(task.name)
    names = tuple(f.name for f in base.obs_fields)
    want = tuple(f.name for f in task.obs_fields)
    if (base.obs_dim, base.action_dim) != (sizes.obs_dim, sizes.action_dim) or (
        names and names != want
    ):
        raise ElicitError(
            f"base demonstrations (obs_dim={base.obs_dim}, action_dim={base.action_dim}, fields "
            f"{list(names)}) do not match task '{task.name}' (obs_dim={sizes.obs_dim}, fields "
            f"{list(want)})",
            config.base_demos,
        )


def load_session_policy(
    path: str | Path,
    which: str | int,
    seed: int | None,
    base: Demos,
    base_path: str | Path,
    task: str | None = None,
) -> LoadedPolicy:
    """The policy a session or a watched folder scores with, loaded by the one loader and
    checked: the task's sizes (when ``task`` is given), the base demonstrations' sizes and
    observation fields, and a feed-forward kind (scored one state at a time).

    Raises:
      ElicitError: one line naming the checkpoint or the base demonstrations.
    """
    from elicit_jax.compat.score import check_dims
    from elicit_jax.policy.checkpoint import check_compatible
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.sim.registry import task_entry

    sizes = task_entry(task) if task is not None else None
    loaded = load_policy(path, which, seed=seed, task=sizes)
    names = tuple(f.name for f in base.obs_fields)
    check_dims(loaded.policy, base.obs_dim, base.action_dim, str(path), names)
    check_compatible(loaded.policy, base, base_path)
    check_live_policy(loaded.policy, str(path))
    return loaded


def task_action_names(task: Any) -> tuple[str, ...]:
    """Names of a simulated task's action dimensions."""
    from elicit_jax.sim.env import ACTION_NAMES

    return tuple(ACTION_NAMES)


def load_inputs(config: SessionConfig) -> dict[str, Any]:
    """Load and check the task, base demonstrations, policy and operator of ``config``.

    Returns:
      ``task``, ``base`` (the demonstrations), ``policy`` (a ``LoadedPolicy``), ``seed``,
      ``train_config`` (None without retraining batches) and ``operator``.

    Raises:
      ElicitError: one line naming the input that does not fit.
    """
    from elicit_jax.data.demos import read_demos
    from elicit_jax.elicit import people  # noqa: F401  (registers the person: operators)
    from elicit_jax.elicit.operators import OperatorContext, make_session_operator
    from elicit_jax.sim.env import make_task

    # a robosuite task is a task like any other here: its environment is built (in this
    # process) when the first episode begins
    task = make_task(config.task, **({"horizon": config.horizon} if config.horizon else {}))
    base = read_demos(config.base_demos)
    _check_base(config, task, base)
    loaded = load_session_policy(
        config.policy, config.which, config.policy_seed, base, config.base_demos, task.name
    )
    return {
        "task": task,
        "base": base,
        "policy": loaded,
        "seed": loaded.seed,
        "train_config": loaded.train_config() if config.batch else None,
        "operator": make_session_operator(
            config.operator, OperatorContext(task, base, config.dagger)
        ),
    }
