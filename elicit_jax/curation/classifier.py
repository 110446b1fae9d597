"""A small state classifier (success vs failure), several trained at once with early stopping.

:class:`StateClassifier` maps a (normalised) state to the logit of "this state belongs to a
successful rollout". :func:`fit_classifiers` trains K of them at once — one per candidate
training set, each a subset of the rows of one shared array — with ``jax.vmap`` over the
candidates and nested ``lax.scan`` over evaluation rounds and steps. Every ``eval_every``
steps each candidate's binary cross-entropy on a shared validation set is measured and the
parameters with the lowest so far are kept (early stopping on held-out data). The whole fit is
a pure function of its PRNG key.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from elicit_jax.errors import ElicitError
from elicit_jax.policy.config import MAX_BATCH_SIZE, MAX_LR
from elicit_jax.policy.loop import keep_best


@dataclasses.dataclass(frozen=True)
class ClassifierConfig:
    """Classifier and training settings (defaults follow the Demo-SCORE release: a 2 × 8 MLP
    with dropout 0.3, AdamW with weight decay 0.1, successes weighted 4:1).

    Attributes:
      hidden: hidden layer sizes.
      dropout: dropout rate after each hidden layer.
      lr: AdamW learning rate.
      weight_decay: AdamW weight decay.
      batch_size: states per step.
      steps: training steps.
      eval_every: steps between validation rounds.
      success_weight: weight of a success state's loss relative to a failure state's.
      seed: PRNG seed.
    """

    hidden: tuple[int, ...] = (8, 8)
    dropout: float = 0.3
    lr: float = 1e-3
    weight_decay: float = 0.1
    batch_size: int = 1024
    steps: int = 2000
    eval_every: int = 50
    success_weight: float = 4.0
    seed: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "hidden", tuple(int(h) for h in self.hidden))
        if not self.hidden or min(self.hidden) < 1:
            raise ElicitError(f"classifier hidden sizes must be positive, got {self.hidden}")
        if not 0.0 <= self.dropout < 1.0:
            raise ElicitError(f"classifier dropout must be in [0, 1), got {self.dropout}")
        if self.eval_every < 1 or self.steps < self.eval_every:
            raise ElicitError(
                f"classifier needs steps >= eval_every >= 1, got {self.steps}, {self.eval_every}"
            )
        for name in ("lr", "batch_size", "success_weight"):
            if not getattr(self, name) > 0:
                raise ElicitError(f"classifier {name} must be positive")
        # the same limits as the base policy's training (TrainConfig)
        if not (math.isfinite(self.lr) and self.lr <= MAX_LR):
            raise ElicitError(f"classifier lr must be a number in (0, {MAX_LR:g}], got {self.lr}")
        if self.batch_size > MAX_BATCH_SIZE:
            raise ElicitError(
                f"classifier batch_size must be in 1..{MAX_BATCH_SIZE}, got {self.batch_size}"
            )

    @property
    def n_rounds(self) -> int:
        return self.steps // self.eval_every


class StateClassifier(nn.Module):
    """state ``(..., O)`` -> logit ``(...)``: Dense -> ReLU -> dropout per hidden layer."""

    hidden: Sequence[int]
    dropout: float

    @nn.compact
    def __call__(self, x: jax.Array, train: bool = False) -> jax.Array:
        for size in self.hidden:
            x = nn.relu(nn.Dense(size)(x))
            x = nn.Dropout(self.dropout, deterministic=not train)(x)
        return nn.Dense(1)(x)[..., 0]


@struct.dataclass
class FitState:
    """One candidate's training state.

    Attributes:
      params: current parameters.
      opt_state: AdamW state.
      best_params: parameters at the lowest validation loss so far.
      best_loss: that loss.
      best_step: its step (0 before the first validation round).
    """

    params: Any
    opt_state: Any
    best_params: Any
    best_loss: jax.Array
    best_step: jax.Array


def bce(logits: jax.Array, labels: jax.Array, weights: jax.Array | None = None) -> jax.Array:
    """(Weighted) mean binary cross-entropy of ``logits`` against 0/1 ``labels``."""
    per = optax.sigmoid_binary_cross_entropy(logits, labels.astype(logits.dtype))
    if weights is None:
        return jnp.mean(per)
    return jnp.sum(per * weights) / jnp.maximum(jnp.sum(weights), 1e-12)


@functools.lru_cache(maxsize=4)
def _fit_fn(config: ClassifierConfig, obs_dim: int):
    """Jitted ``fit(key, x, y, rows (K, R), n_rows (K,), val_x, val_y)`` -> (FitState batched
    over K, validation curve (K, n_rounds))."""
    module = StateClassifier(config.hidden, config.dropout)
    tx = optax.adamw(config.lr, weight_decay=config.weight_decay)

    def one(key, x, y, rows, n_rows, val_x, val_y):
        k_init, k_run = jax.random.split(key)
        params = module.init(k_init, jnp.zeros((1, obs_dim)))["params"]
        state = FitState(params, tx.init(params), params, jnp.asarray(jnp.inf), jnp.asarray(0))

        def step(carry, k):
            params, opt_state = carry
            k_idx, k_drop = jax.random.split(k)
            pick = jnp.floor(jax.random.uniform(k_idx, (config.batch_size,)) * n_rows)
            idx = rows[pick.astype(jnp.int32)]
            xb, yb = x[idx], y[idx]
            w = jnp.where(yb, config.success_weight, 1.0)

            def loss_fn(p):
                logits = module.apply({"params": p}, xb, True, rngs={"dropout": k_drop})
                return bce(logits, yb, w)

            grads = jax.grad(loss_fn)(params)
            updates, opt_state = tx.update(grads, opt_state, params)
            return (optax.apply_updates(params, updates), opt_state), None

        def round_(state, r):
            keys = jax.random.split(jax.random.fold_in(k_run, r), config.eval_every)
            (params, opt_state), _ = jax.lax.scan(step, (state.params, state.opt_state), keys)
            loss = bce(module.apply({"params": params}, val_x, False), val_y)
            state = keep_best(state, params, opt_state, loss, best_step=(r + 1) * config.eval_every)
            return state, loss

        return jax.lax.scan(round_, state, jnp.arange(config.n_rounds))

    batched = jax.vmap(one, in_axes=(0, None, None, 0, 0, None, None))
    return jax.jit(batched)


def fit_classifiers(
    config: ClassifierConfig,
    x: np.ndarray,
    y: np.ndarray,
    candidates: Sequence[np.ndarray],
    val_x: np.ndarray,
    val_y: np.ndarray,
) -> tuple[FitState, np.ndarray]:
    """Train one classifier per candidate training set, early-stopped on the validation set.

    Args:
      config: classifier settings.
      x: (M, O) normalised states.
      y: (M,) bool labels (True = from a successful rollout).
      candidates: K arrays of row indices into ``x``, one training set each.
      val_x: (V, O) normalised validation states (shared by every candidate).
      val_y: (V,) their labels.

    Returns:
      ``(state, curve)``: the K fits (leaves with a leading K axis; ``best_params`` is the
      early-stopped classifier) and the validation loss per round, ``(K, n_rounds)``.
    """
    if not candidates or any(len(c) == 0 for c in candidates):
        raise ElicitError("classifier: every candidate training set needs at least one state")
    width = max(len(c) for c in candidates)
    rows = np.zeros((len(candidates), width), np.int32)
    for k, c in enumerate(candidates):
        rows[k, : len(c)] = c
    n_rows = np.array([len(c) for c in candidates], np.float32)
    keys = jax.random.split(jax.random.key(config.seed), len(candidates))
    fit = _fit_fn(config, int(x.shape[1]))
    state, curve = fit(
        keys,
        jnp.asarray(x, jnp.float32),
        jnp.asarray(y, bool),
        jnp.asarray(rows),
        jnp.asarray(n_rows),
        jnp.asarray(val_x, jnp.float32),
        jnp.asarray(val_y, bool),
    )
    return state, np.asarray(curve)


def predict(config: ClassifierConfig, params: Any, x: np.ndarray) -> np.ndarray:
    """(M,) probability of success for normalised states ``x (M, O)`` under one classifier."""
    module = StateClassifier(config.hidden, config.dropout)
    logits = jax.jit(lambda p, v: module.apply({"params": p}, v, False))(
        params, jnp.asarray(x, jnp.float32)
    )
    return np.asarray(jax.nn.sigmoid(logits), np.float64)
