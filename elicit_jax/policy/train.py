"""Train a base policy and write its checkpoint directory (see :mod:`.checkpoint`; written by
:mod:`.run_dir`).

:func:`train_policy` does the host-side set-up once (episode split, normalisation, windows),
compiles one chunk of epochs (:func:`elicit_jax.policy.loop.make_chunk_fn`) and calls it
until the run is done, showing a rich progress bar and saving checkpoints between chunks.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import atomic_path, refuse_overwriting_inputs
from elicit_jax.data.demos import Demos
from elicit_jax.errors import ElicitError
from elicit_jax.policy import checkpoint as ckpt
from elicit_jax.policy.config import TrainConfig
from elicit_jax.policy.dataset import TrainData, demos_sha256, prepare
from elicit_jax.policy.kinds import model_kind
from elicit_jax.policy.run_dir import check_destination, write_run


def chunk_epochs(config: TrainConfig) -> int:
    """Epochs per jitted chunk: the largest divisor of ``gcd(epochs, checkpoint_every)`` not
    above ``progress_every``, so all chunks share one compiled function."""
    g = math.gcd(config.epochs, config.checkpoint_every)
    return max(d for d in range(1, min(g, config.progress_every) + 1) if g % d == 0)


def _loop_spec(config: TrainConfig, data: TrainData, obs_dim: int, action_dim: int) -> Any:
    from elicit_jax.policy.loop import LoopSpec

    return LoopSpec(
        kind=config.model,
        module=_template(config, data, obs_dim, action_dim).module,
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


def _template(
    config: TrainConfig,
    data: TrainData,
    obs_dim: int,
    action_dim: int,
    obs_fields: tuple[str, ...] = (),
) -> Any:
    """The policy a run of ``config`` trains, without parameters: the loop trains its
    ``module``, and the checkpoint records its spec."""
    from elicit_jax.policy.base import Policy

    return Policy(
        params=None,
        obs_mean=data.obs_mean,
        obs_std=data.obs_std,
        kind=config.model,
        obs_dim=obs_dim,
        action_dim=action_dim,
        n_members=config.ensemble_size,
        hidden=config.hidden,
        dropout=config.dropout,
        n_components=config.n_components,
        reset_every=config.seq_len if model_kind(config.model).recurrent else 0,
        obs_fields=obs_fields,
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
        results = _train_groups(tmp, config, demos, data, progress, out_dir)
        notes = training_warnings(config, demos.action, results)
        fields = tuple(f.name for f in demos.obs_fields)
        template = _template(config, data, demos.obs_dim, demos.action_dim, fields)
        write_run(tmp, config, demos, data, template, data_hash, inputs, results, notes)
        progress.summary(results)
        progress.warn(notes)
    return out_dir


def check_losses(
    seeds: tuple[int, ...], done: int, train: np.ndarray, val: np.ndarray, out: str | Path
) -> None:
    """Stop a run whose loss became non-finite (NaN or inf): it diverged, and its "best"
    parameters would be whatever came before (at worst the random initialisation).

    Args:
      seeds: the seeds of ``train``'s and ``val``'s leading axis.
      done: epochs done after this chunk.
      train: (S, n, K) training losses of the chunk's n epochs; val: the same (NaN when there
        is no validation split, which is not a divergence).
      out: the run directory, named in the error.

    Raises:
      ElicitError: one line naming the run, the seed and the first bad epoch.
    """
    n = train.shape[1]
    for i, s in enumerate(seeds):
        bad = ~np.isfinite(train[i]).all(axis=-1)
        has_val = np.isfinite(val[i]).any()
        if has_val:
            bad |= ~np.isfinite(val[i]).all(axis=-1)
        if bad.any():
            epoch = done - n + int(np.flatnonzero(bad)[0]) + 1
            raise ElicitError(
                f"training diverged: seed {s}'s loss is not finite (NaN or inf) at epoch "
                f"{epoch}; nothing was written (lower --lr, or check the data)",
                out,
            )


def _train_groups(
    tmp: Path,
    config: TrainConfig,
    demos: Demos,
    data: TrainData,
    progress: Any,
    out: str | Path = "<run>",
) -> dict[int, tuple[np.ndarray, np.ndarray, int, float]]:
    """Train every seed (all at once, or one after another without ``vmap_seeds``), saving
    the periodic and best parameters under ``tmp``; seed -> (train loss, val loss, best
    epoch, seconds). A loss that becomes non-finite stops the run (:func:`check_losses`)."""
    groups = [config.seeds] if config.vmap_seeds else [(s,) for s in config.seeds]
    results = {}
    for seeds in groups:
        progress.start_group(seeds)
        t0 = time.perf_counter()

        def on_chunk(done: int, states: Any, tl: Any, vl: Any, dt: float, seeds=seeds):
            check_losses(seeds, done, np.asarray(tl), np.asarray(vl), out)
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
