"""Retraining between batches: π_new on D_base ∪ the accepted demonstrations so far.

The training config is the base policy's own (read from its checkpoint header), with one
training seed — the seed of the policy the session loaded — so π_new differs from π_base
only in its data. Each batch's policy is a training run directory
``SESSION/policies/batch<b>/``, written atomically: a kill during training leaves no
half-written policy, and a resumed session trains that batch again.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from elicit_jax.artifact import read_header
from elicit_jax.errors import ElicitError


def policy_train_config(policy_path: str | Path, seed: int) -> Any:
    """The :class:`~elicit_jax.policy.config.TrainConfig` the policy at ``policy_path`` was
    trained with, restricted to training seed ``seed``."""
    from elicit_jax.policy.config import TrainConfig

    header = read_header(policy_path)
    if "config" not in header or not header["config"]:
        raise ElicitError(
            "checkpoint header records no training config to retrain with", policy_path
        )
    config = TrainConfig.from_dict(header["config"])
    return dataclasses.replace(config, seeds=(int(seed),))


def loaded_seed(policy_path: str | Path, seed: int | None) -> int:
    """The training seed of the checkpoint a session loads (a seed dir, or a run's seed)."""
    from elicit_jax.policy.checkpoint import seed_dirs

    dirs = seed_dirs(policy_path)
    if seed is not None:
        return int(seed)
    if len(dirs) != 1:
        raise ElicitError(f"holds seeds {sorted(dirs)}; pick one with --policy-seed", policy_path)
    return int(next(iter(dirs)))


def train_batch_policy(
    out_dir: Path,
    base: Any,
    accepted: Any,
    config: Any,
    inputs: dict[str, str | Path],
    quiet: bool = True,
) -> Path:
    """Train π_new on ``base`` ∪ ``accepted`` (``Demos``) into ``out_dir``."""
    from elicit_jax.data.demos import concat_demos
    from elicit_jax.policy.train import train_policy

    data = concat_demos([base, accepted])
    return train_policy(data, config, out_dir, inputs=inputs, quiet=quiet)
