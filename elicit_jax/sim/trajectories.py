"""Rollout trajectories: every state a policy acted in during ``evaluate``, the action it took
and its rollout's outcome (``elicit-jax evaluate --trajectories``).

The per-rollout table of ``evaluate`` says whether each rollout succeeded; methods that learn
from rollouts (CUPID's policy-gradient estimate of expected return,
:mod:`~elicit_jax.curation.cupid`) also need the state-action pairs. This artifact (kind
``rollout-steps``) holds one Parquet row per control step the policy acted in: the policy,
training seed and checkpoint, the rollout index and its initial-state seed, the step, the
observation and the action taken (exploration noise included), and the rollout's success and
return. ``action_noise`` in the header is the std of the Gaussian exploration noise added to
the policy's actions (0: the deterministic policy's own actions).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError

STEPS_KIND = "rollout-steps"
STEPS_SCHEMA_VERSION = 1


@dataclasses.dataclass(frozen=True)
class TrajectoryConfig:
    """Where and how to record rollout trajectories.

    Attributes:
      out: path of the ``rollout-steps`` Parquet artifact.
      action_noise: std of Gaussian exploration noise added to each action (seeded by the
        rollout's initial-state seed); recorded actions include it.
    """

    out: str
    action_noise: float = 0.0

    def __post_init__(self) -> None:
        if not np.isfinite(self.action_noise) or self.action_noise < 0:
            raise ElicitError(f"--action-noise must be a finite std >= 0, got {self.action_noise}")


@dataclasses.dataclass(frozen=True)
class Trajectories:
    """Recorded rollout steps, flattened.

    Attributes:
      obs: (M, O) states the policy acted in.
      action: (M, A) actions taken.
      rollout: (M,) index of each step's rollout into ``success`` / ``ret``.
      success: (R,) outcome of each rollout.
      ret: (R,) return of each rollout.
      action_noise: the exploration noise's std.
      header: the artifact's header.
    """

    obs: np.ndarray
    action: np.ndarray
    rollout: np.ndarray
    success: np.ndarray
    ret: np.ndarray
    action_noise: float
    header: dict[str, Any]


def steps_frame(ref: Any, seeds: np.ndarray, out: dict[str, np.ndarray]) -> Any:
    """Per-step rows of one policy's rollouts (``out`` from a rollout with recorded states)."""
    import pandas as pd

    mask = np.asarray(out["state_mask"], bool)
    r, t = np.nonzero(mask)
    return pd.DataFrame(
        {
            "policy": ref.label,
            "seed": np.int32(ref.seed),
            "checkpoint": ref.checkpoint,
            "rollout": r.astype(np.int32),
            "init_seed": np.asarray(seeds, np.int64)[r],
            "step": t.astype(np.int32),
            "obs": list(np.asarray(out["states"], np.float32)[r, t]),
            "action": list(np.asarray(out["actions"], np.float32)[r, t]),
            "success": np.asarray(out["success"], bool)[r],
            "ret": np.asarray(out["ret"], np.float32)[r],
        }
    )


def write_trajectories(
    frames: Sequence[Any], config: TrajectoryConfig, header: dict[str, Any]
) -> None:
    """Write the recorded steps of every policy as one ``rollout-steps`` artifact."""
    import pandas as pd
    import pyarrow as pa

    from elicit_jax.artifact import make_header, write_parquet

    table = pd.concat(frames, ignore_index=True)
    head = make_header(
        STEPS_KIND,
        STEPS_SCHEMA_VERSION,
        **header,
        action_noise=config.action_noise,
        n_rows=len(table),
    )
    write_parquet(config.out, pa.Table.from_pandas(table, preserve_index=False), head)


def read_trajectories(
    path: str | Path,
    policy: str | None = None,
    seed: int | None = None,
    checkpoint: str | None = None,
) -> Trajectories:
    """Read a ``rollout-steps`` artifact (only ``policy``'s rows when given; a file of several
    policies needs one named), optionally only one training seed's and checkpoint's rows.

    Raises:
      ElicitError: not such an artifact, several policies and none chosen, no steps, or
        non-finite states/actions.
    """
    import pyarrow.parquet as pq

    from elicit_jax.artifact import read_artifact

    what = "rollout trajectories (elicit-jax evaluate --trajectories)"
    header = read_artifact(path, STEPS_KIND, STEPS_SCHEMA_VERSION, what=what)
    df = pq.read_table(path).to_pandas()
    labels = sorted(set(df["policy"]))
    have = sorted({(int(s), str(c)) for s, c in zip(df["seed"], df["checkpoint"], strict=True)})
    if policy is not None:
        df = df[df["policy"] == policy]
    elif len(labels) > 1:
        raise ElicitError(f"holds rollouts of several policies ({', '.join(labels)})", path)
    if seed is not None:
        df = df[df["seed"] == seed]
    if checkpoint is not None:
        df = df[df["checkpoint"].astype(str) == str(checkpoint)]
    if df.empty:
        which = f"policy={policy}, seed={seed}, checkpoint={checkpoint}"
        listed = ", ".join(f"seed {s} checkpoint {c}" for s, c in have)
        raise ElicitError(f"no rollout steps of {which} (it has {listed})", path)
    key = list(zip(df["seed"], df["checkpoint"], df["rollout"], strict=True))
    uniq = {k: i for i, k in enumerate(dict.fromkeys(key))}
    rollout = np.asarray([uniq[k] for k in key], np.int64)
    first = np.unique(rollout, return_index=True)[1]
    obs = np.stack(df["obs"].to_numpy()).astype(np.float32)
    action = np.stack(df["action"].to_numpy()).astype(np.float32)
    if not (np.isfinite(obs).all() and np.isfinite(action).all()):
        raise ElicitError("non-finite states or actions in rollout trajectories", path)
    return Trajectories(
        obs=obs,
        action=action,
        rollout=rollout,
        success=df["success"].to_numpy(bool)[first],
        ret=df["ret"].to_numpy(np.float64)[first],
        action_noise=float(header.get("action_noise", 0.0)),
        header=header,
    )
