"""Train a base policy and write its checkpoint directory (see :mod:`.checkpoint`).

:func:`train_policy` does the host-side set-up once (episode split, normalisation, windows),
compiles one chunk of epochs (:func:`elicit_jax.policy.loop.make_chunk_fn`) and calls it
until the run is done, showing a rich progress bar and saving checkpoints between chunks.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import (
    atomic_path,
    dumps,
    make_header,
    read_header,
    refuse_overwriting_inputs,
    write_json,
    write_parquet,
)
from elicit_jax.data.demos import Demos
from elicit_jax.data.duplicates import episode_digests
from elicit_jax.errors import ElicitError
from elicit_jax.policy import checkpoint as ckpt
from elicit_jax.policy.config import TrainConfig
from elicit_jax.policy.dataset import (
    TrainData,
    action_stats,
    demos_sha256,
    prepare,
)
from elicit_jax.policy.kinds import model_kind


def chunk_epochs(config: TrainConfig) -> int:
    """Epochs per jitted chunk: the largest divisor of ``gcd(epochs, checkpoint_every)`` not
    above ``progress_every``, so all chunks share one compiled function."""
    g = math.gcd(config.epochs, config.checkpoint_every)
    return max(d for d in range(1, min(g, config.progress_every) + 1) if g % d == 0)


def _loop_spec(config: TrainConfig, data: TrainData, obs_dim: int, action_dim: int) -> Any:
    from elicit_jax.policy.kinds import make_module
    from elicit_jax.policy.loop import LoopSpec

    module = make_module(
        config.model,
        config.hidden,
        action_dim,
        config.dropout,
        config.n_components,
        layer_norm_eps=config.layer_norm_eps,
        dropout_last=config.dropout_last,
        mdn_min_std=config.mdn_min_std,
    )
    return LoopSpec(
        kind=config.model,
        module=module,
        n_members=config.ensemble_size,
        obs_dim=obs_dim,
        batch_size=config.batch_size,
        n_train=data.n_train,
        n_val=data.n_val,
        lr=config.lr,
        grad_clip=config.grad_clip,
        bootstrap=config.bootstrap,
        loss_sum=config.loss == "sum",
    )


def _template(config: TrainConfig, demos: Demos, data: TrainData, params: Any) -> Any:
    from elicit_jax.policy.base import Policy

    return Policy(
        params=params,
        obs_mean=data.obs_mean,
        obs_std=data.obs_std,
        kind=config.model,
        obs_dim=demos.obs_dim,
        action_dim=demos.action_dim,
        n_members=config.ensemble_size,
        hidden=config.hidden,
        dropout=config.dropout,
        n_components=config.n_components,
        reset_every=config.seq_len if model_kind(config.model).recurrent else 0,
        obs_fields=tuple(f.name for f in demos.obs_fields),
        layer_norm_eps=config.layer_norm_eps,
        dropout_last=config.dropout_last,
        mdn_min_std=config.mdn_min_std,
    )


def _seed_slice(tree: Any, i: int) -> Any:
    import jax

    return jax.tree.map(lambda x: np.asarray(x[i]), tree)


def train_states(
    config: TrainConfig,
    data: TrainData,
    obs_dim: int,
    action_dim: int,
    seeds: tuple[int, ...],
    on_chunk: Any = None,
) -> tuple[Any, np.ndarray, np.ndarray]:
    """Train ``seeds`` together (vmapped); a pure function of the seeds and the data.

    Args:
      on_chunk: optional ``fn(epochs_done, states, train (S, n, K), val (S, n, K), seconds)``
        called on the host after every chunk.

    Returns:
      (final stacked states, train loss (S, epochs, K), val loss (S, epochs, K)).
    """
    import jax
    import jax.numpy as jnp

    from elicit_jax.policy.loop import init_states, make_chunk_fn

    spec = _loop_spec(config, data, obs_dim, action_dim)
    arrays = {
        "obs": data.obs,
        "action": data.action,
        "train_windows": data.train_windows,
        "train_mask": data.train_mask,
        "val_windows": data.val_windows,
        "val_mask": data.val_mask,
    }
    device_data = jax.tree.map(jnp.asarray, arrays)
    n = chunk_epochs(config)
    fn = make_chunk_fn(spec, n)
    states = init_states(spec, seeds)
    train_hist, val_hist = [], []
    for first in range(0, config.epochs, n):
        t0 = time.perf_counter()
        states, (tl, vl) = fn(states, device_data, jnp.asarray(first, jnp.int32))
        tl, vl = np.asarray(tl), np.asarray(vl)
        train_hist.append(tl)
        val_hist.append(vl)
        if on_chunk is not None:
            on_chunk(first + n, states, tl, vl, time.perf_counter() - t0)
    return states, np.concatenate(train_hist, axis=1), np.concatenate(val_hist, axis=1)


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


def training_warnings(
    config: TrainConfig, action: np.ndarray, results: Mapping[int, tuple[Any, Any, int, float]]
) -> list[str]:
    """What the user should know about a finished run: an ensemble of one (ν ≡ 0), seeds whose
    best epoch is the last (still improving; said only when there is a validation set: without
    one the best epoch is picked by training loss, which almost always falls to the end),
    action dims that distort ℓ."""
    out = []
    if config.ensemble_size == 1 and not model_kind(config.model).own_spread:
        out.append(
            "one ensemble member: novelty is 0 for every state, so every state counts as "
            "familiar and compatibility rests on the likelihood error alone (the paper uses 5)"
        )
    last = [
        s
        for s, (_, val, best, _) in sorted(results.items())
        if best == config.epochs and (val is None or np.isfinite(np.asarray(val, float)).any())
    ]
    if last and config.epochs > 1:
        out.append(
            f"seed(s) {', '.join(map(str, last))}: the best validation loss is at the last "
            f"epoch ({config.epochs}), so the policy was still improving; more epochs may help"
        )
    from elicit_jax.data.validation import action_dim_warnings

    return out + action_dim_warnings(action)


def _nan_to_none(x: float) -> float | None:
    return None if not np.isfinite(x) else float(x)


def check_destination(out_dir: Path, config: TrainConfig, data_hash: str, overwrite: bool) -> None:
    """Refuse to replace ``out_dir`` unless it is empty, or it holds a training run and either
    ``overwrite`` is set or that run is of this very config on these very data (training is
    deterministic: nothing is lost). Anything else (a file, a folder of notes) is never
    replaced, ``overwrite`` or not."""
    if not out_dir.exists():
        return
    if out_dir.is_dir() and not any(out_dir.iterdir()):
        return
    try:
        header = read_header(out_dir) if out_dir.is_dir() else {}
    except ElicitError:
        header = {}
    if header.get("kind") == ckpt.RUN_KIND:
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


def train_policy(
    demos: Demos,
    config: TrainConfig,
    out_dir: str | Path,
    *,
    inputs: Mapping[str, str | Path] | None = None,
    quiet: bool = False,
    overwrite: bool = False,
) -> Path:
    """Train ``config.seeds`` policies on ``demos`` and write the run directory.

    Args:
      demos: training demonstrations.
      config: the training configuration.
      out_dir: run directory to create (replaced atomically when it holds a run of the same
        config and data, or with ``overwrite``).
      inputs: name -> path of input artifacts, hashed into the headers (e.g. the demos file).
      quiet: no progress bar or summary.
      overwrite: replace whatever ``out_dir`` holds.

    Returns:
      ``out_dir`` as a Path. Each seed's checkpoint is ``out_dir / f"seed{seed}"``.

    Raises:
      ElicitError: ``out_dir`` holds another run (or anything else) and not ``overwrite``;
        ``out_dir`` is or holds one of the inputs.
    """
    from elicit_jax.policy.progress import TrainProgress

    out_dir = Path(out_dir)
    refuse_overwriting_inputs([out_dir], (inputs or {}).values())
    data_hash = demos_sha256(demos)
    check_destination(out_dir, config, data_hash, overwrite)
    window = config.seq_len if model_kind(config.model).recurrent else 1
    data = prepare(demos, config.val_fraction, window)
    with atomic_path(out_dir) as tmp, TrainProgress(config, data.n_train, quiet) as progress:
        results = _train_groups(tmp, config, demos, data, progress)
        notes = _write_run(tmp, config, demos, data, data_hash, inputs, results)
        progress.summary(results)
        progress.warn(notes)
    return out_dir


def _train_groups(
    tmp: Path, config: TrainConfig, demos: Demos, data: TrainData, progress: Any
) -> dict[int, tuple[np.ndarray, np.ndarray, int, float]]:
    """Train every seed (all at once, or one after another without ``vmap_seeds``), saving
    the periodic and best parameters under ``tmp``; seed -> (train loss, val loss, best
    epoch, seconds)."""
    groups = [config.seeds] if config.vmap_seeds else [(s,) for s in config.seeds]
    results = {}
    for seeds in groups:
        progress.start_group(seeds)
        t0 = time.perf_counter()

        def on_chunk(done: int, states: Any, tl: Any, vl: Any, dt: float, seeds=seeds):
            progress.update(done, tl, vl, dt)
            if done % config.checkpoint_every == 0 or done == config.epochs:
                for i, s in enumerate(seeds):
                    params = _seed_slice(states.params, i)
                    ckpt.save_params(tmp / f"seed{s}" / "params" / ckpt.epoch_file(done), params)

        states, train, val = train_states(
            config, data, demos.obs_dim, demos.action_dim, seeds, on_chunk
        )
        seconds = time.perf_counter() - t0
        for i, s in enumerate(seeds):
            results[s] = (train[i], val[i], int(states.best_epoch[i]), seconds)
            ckpt.save_params(
                tmp / f"seed{s}" / "params" / "best.npz", _seed_slice(states.best_params, i)
            )
    return results


def _write_run(
    tmp: Path,
    config: TrainConfig,
    demos: Demos,
    data: TrainData,
    data_hash: str,
    inputs: Mapping[str, str | Path] | None,
    results: Mapping[int, tuple[np.ndarray, np.ndarray, int, float]],
) -> list[str]:
    """Write every seed's files and the run's header into ``tmp``; returns the run's
    warnings (:func:`training_warnings`)."""
    template = _template(config, demos, data, params=None)
    digests = {str(e): d for e, d in episode_digests(demos).items()}
    for s, (train, val, best_epoch, seconds) in results.items():
        _write_seed(
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
    notes = training_warnings(config, demos.action, results)
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
    return notes


def _write_seed(
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
