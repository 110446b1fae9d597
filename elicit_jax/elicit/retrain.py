"""Retraining between batches: π_new on D_base ∪ the accepted demonstrations so far.

The training config is the base policy's own (read with it, once:
:meth:`elicit_jax.policy.loaded.LoadedPolicy.train_config`), with one training seed — the
seed of the policy the session loaded — so π_new differs from π_base only in its data. Each
batch's policy is a training run directory ``SESSION/policies/batch<b>/``, written atomically:
a kill during training leaves no half-written policy, and a resumed session trains that batch
again.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


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
