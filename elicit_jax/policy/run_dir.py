"""Writing a training run's directory: the destination check, every seed's files, the
run's header (the layout is :mod:`elicit_jax.policy.checkpoint`'s).

:func:`elicit_jax.policy.train.train_policy` trains into a temporary directory and calls
:func:`write_run` there before renaming it into place, so a run is never half-written.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import (
    dumps,
    make_header,
    read_header,
    refuse_foreign_files,
    write_json,
    write_parquet,
)
from elicit_jax.data.demos import Demos
from elicit_jax.data.duplicates import episode_digests
from elicit_jax.errors import ElicitError
from elicit_jax.policy import checkpoint as ckpt
from elicit_jax.policy.config import TrainConfig
from elicit_jax.policy.dataset import TrainData, action_stats


def check_destination(out_dir: Path, config: TrainConfig, data_hash: str, overwrite: bool) -> None:
    """Refuse to replace ``out_dir`` unless it is empty, or it holds a training run and either
    ``overwrite`` is set or that run is of this very config on these very data (training is
    deterministic: nothing is lost). Anything else (a file, a folder of notes) is never
    replaced, ``overwrite`` or not; nor is a run holding files a run does not write (a
    user's ``NOTES.md``, ``eval/``, ``seed0/mine.txt``): they are named instead."""
    if not out_dir.exists():
        return
    if out_dir.is_dir() and not any(out_dir.iterdir()):
        return
    try:
        header = read_header(out_dir) if out_dir.is_dir() else {}
    except ElicitError:
        header = {}
    if header.get("kind") == ckpt.RUN_KIND:
        refuse_foreign_files(out_dir, ckpt.run_owns, "a training run")
        if overwrite:
            return
        same = header.get("config") == json.loads(dumps(config.to_dict()))
        if same and header.get("data_sha256") == data_hash:
            return
        what = "a training run of another config" if not same else "a run trained on other data"
    else:
        raise ElicitError(
            "already holds something that is not a training run; elicit-jax replaces only "
            "training runs (with --overwrite): choose another --out",
            out_dir,
        )
    raise ElicitError(
        f"already holds {what}; pass --overwrite to replace it, or choose another --out", out_dir
    )


def write_run(
    tmp: Path,
    config: TrainConfig,
    demos: Demos,
    data: TrainData,
    template: Any,
    data_hash: str,
    inputs: Mapping[str, str | Path] | None,
    results: Mapping[int, tuple[np.ndarray, np.ndarray, int, float]],
    notes: list[str],
) -> None:
    """Write every seed's files (:func:`write_seed`) and the run's header into ``tmp``.

    Args:
      tmp: the run directory being written (renamed into place by the caller).
      config: the training config.
      demos: the training demonstrations (their task and episode digests are recorded).
      data: the prepared training data (split, normalisation).
      template: a ``Policy`` without params: the model spec to record.
      data_hash: the demonstrations' content hash.
      inputs: name -> path of the input artifacts, hashed into the headers.
      results: seed -> (train loss, val loss, best epoch, seconds).
      notes: the run's warnings, recorded in its header.
    """
    digests = {str(e): d for e, d in episode_digests(demos).items()}
    for s, (train, val, best_epoch, seconds) in results.items():
        write_seed(
            tmp / f"seed{s}",
            config,
            template,
            data,
            data_hash,
            inputs,
            s,
            train,
            val,
            best_epoch,
            seconds,
            digests,
        )
    write_json(
        tmp / "artifact.json",
        make_header(
            ckpt.RUN_KIND,
            ckpt.SCHEMA_VERSION,
            config=config.to_dict(),
            inputs=inputs,
            seed=list(config.seeds),
            seeds=list(config.seeds),
            seed_dirs={str(s): f"seed{s}" for s in config.seeds},
            model=ckpt.policy_spec(template),
            data_sha256=data_hash,
            task=demos.task,
            warnings=notes,
        ),
    )


def write_seed(
    seed_dir: Path,
    config: TrainConfig,
    template: Any,
    data: TrainData,
    data_hash: str,
    inputs: Mapping[str, str | Path] | None,
    seed: int,
    train: np.ndarray,
    val: np.ndarray,
    best_epoch: int,
    seconds: float,
    digests: Mapping[str, str],
) -> None:
    """Write one seed's normalisation stats, loss curve and header (``episode_sha256``: the
    content hash of every training demonstration, by episode id, so thresholds can be checked
    against the training data later, whatever file it is found in)."""
    act_mean, act_std = action_stats(data)
    with open(seed_dir / "normalization.npz", "wb") as f:
        np.savez(
            f,
            obs_mean=data.obs_mean,
            obs_std=data.obs_std,
            action_mean=act_mean,
            action_std=act_std,
        )
    header_fields = {
        "model": ckpt.policy_spec(template),
        "obs_dim": template.obs_dim,
        "action_dim": template.action_dim,
        "data_sha256": data_hash,
        "episode_sha256": dict(digests),
        "epochs_saved": sorted(
            e
            for e in range(1, config.epochs + 1)
            if e % config.checkpoint_every == 0 or e == config.epochs
        ),
        "final_epoch": config.epochs,
        "best_epoch": best_epoch,
        "best_selected_by": "val_loss" if data.n_val else "train_loss",
        "final_train_loss": float(train[-1].mean()),
        "final_val_loss": _nan_to_none(float(val[-1].mean())),
        "best_val_loss": _nan_to_none(float(val[best_epoch - 1].mean())) if best_epoch else None,
        "train_episodes": list(data.train_episodes),
        "val_episodes": list(data.val_episodes),
        "n_train_samples": data.n_train,
        "n_val_samples": data.n_val,
        "train_seconds": round(seconds, 3),
        ckpt.FILE_HASHES: ckpt.file_hashes(seed_dir),
    }
    write_parquet(
        seed_dir / "loss.parquet",
        _loss_table(train, val),
        make_header("loss_curve", 1, config=config.to_dict(), seed=seed),
    )
    ckpt.write_seed_header(
        seed_dir,
        make_header(
            ckpt.CHECKPOINT_KIND,
            ckpt.SCHEMA_VERSION,
            config=config.to_dict(),
            inputs=inputs,
            seed=seed,
            **header_fields,
        ),
    )


def _loss_table(train: np.ndarray, val: np.ndarray) -> Any:
    """Per-epoch loss table from (epochs, K) arrays."""
    import pyarrow as pa

    cols: dict[str, Any] = {
        "epoch": pa.array(np.arange(1, train.shape[0] + 1, dtype=np.int32)),
        "train_loss": pa.array(train.mean(axis=1).astype(np.float64)),
        "val_loss": pa.array(val.mean(axis=1).astype(np.float64)),
    }
    for k in range(train.shape[1]):
        cols[f"train_loss_m{k}"] = pa.array(train[:, k].astype(np.float64))
        cols[f"val_loss_m{k}"] = pa.array(val[:, k].astype(np.float64))
    return pa.table(cols)


def _nan_to_none(x: float) -> float | None:
    return None if not np.isfinite(x) else float(x)
