"""The jitted training loop: a pure function of a PRNG key and the data.

One seed's run is a :class:`TrainState`; epochs and minibatches are nested ``lax.scan``s,
and within an epoch the K members are trained one after another (``lax.map``), each with its
own shuffling, dropout and optional bootstrap sample. Updating all members in one vmapped
step made XLA:CPU batch their matmuls over the member axis, which ran slower than one
member's plain 2-D matmuls (5 x 2 x 256: 1.2-1.4x slower per epoch). Several seeds run at
once with ``vmap`` over a leading seed axis. :func:`make_chunk_fn` compiles ``n`` epochs
once; the host calls it repeatedly to report progress and save checkpoints between chunks.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import optax
from flax import struct

from elicit_jax.policy import kinds

Batch = tuple[jax.Array, jax.Array, jax.Array]


@struct.dataclass
class TrainState:
    """State of one seed's run (leaves of ``params`` have a leading member axis K).

    Attributes:
      params: member-stacked params.
      opt_state: member-stacked Adam state.
      key: the run's PRNG key (epoch keys are ``fold_in(key, epoch)``).
      samples: (K, Nt) int32 each member's training sample indices (bootstrap or identity).
      best_params: params at the lowest validation loss so far.
      best_loss: that loss (member mean); train loss when there is no validation split.
      best_epoch: its epoch (1-based; 0 before training).
    """

    params: Any
    opt_state: Any
    key: jax.Array
    samples: jax.Array
    best_params: Any
    best_loss: jax.Array
    best_epoch: jax.Array


@dataclasses.dataclass(frozen=True)
class LoopSpec:
    """Static shape of a training loop (hashable; fixes what gets compiled)."""

    kind: str
    module: nn.Module
    n_members: int
    obs_dim: int
    batch_size: int
    n_train: int
    n_val: int
    lr: float
    grad_clip: float | None
    bootstrap: bool
    loss_sum: bool = False

    @property
    def n_batches(self) -> int:
        return -(-self.n_train // self.batch_size)

    @property
    def n_val_batches(self) -> int:
        return -(-self.n_val // self.batch_size)

    def optimizer(self) -> optax.GradientTransformation:
        adam = optax.adam(self.lr)
        return (
            adam
            if self.grad_clip is None
            else optax.chain(optax.clip_by_global_norm(self.grad_clip), adam)
        )


def member_loss(
    spec: LoopSpec,
    params: Any,
    obs: jax.Array,
    action: jax.Array,
    mask: jax.Array,
    rng: jax.Array,
    train: bool,
) -> tuple[jax.Array, jax.Array]:
    """Masked mean loss of ONE member on a batch of windows.

    Args:
      obs: (B, L, O) normalised observations; action: (B, L, A); mask: (B, L) weights.
      rng: dropout key. train: dropout on.

    Returns:
      (loss, total weight): the kind's loss (:attr:`ModelKind.loss
      <elicit_jax.policy.kinds.ModelKind>`): squared error averaged over action dims
      (``spec.loss_sum``: summed over them, as the original code does), or the MDN's negative
      log-likelihood.
    """
    weight = jnp.sum(mask)
    reduce = jnp.sum if spec.loss_sum else jnp.mean
    per = kinds.model_kind(spec.kind).loss(spec.module, params, obs, action, rng, train, reduce)
    return jnp.sum(per * mask) / jnp.maximum(weight, 1.0), weight


def _gather(data: dict[str, jax.Array], split: str, idx: jax.Array, w: jax.Array) -> Batch:
    """Windows ``idx (B,)`` of a split -> obs (B, L, O), action (B, L, A), mask (B, L)."""
    rows = data[f"{split}_windows"][idx]
    mask = data[f"{split}_mask"][idx] * w[:, None]
    return data["obs"][rows], data["action"][rows], mask


def _batches(key: jax.Array, samples: jax.Array, n_batches: int, size: int) -> tuple[Any, Any]:
    """Shuffle ONE member's samples ``(Nt,)`` into ``(n_batches, size)`` indices and weights;
    the last batch is filled by wrapping around with weight 0."""
    n = samples.shape[0]
    perm = samples[jax.random.permutation(key, n)]
    total = n_batches * size
    idx = jnp.resize(perm, (total,))
    w = (jnp.arange(total) < n).astype(jnp.float32)
    return idx.reshape(n_batches, size), w.reshape(n_batches, size)


def init_state(spec: LoopSpec, key: jax.Array) -> TrainState:
    """Fresh state of one seed's run from its key."""
    k_init, k_boot, k_run = jax.random.split(key, 3)
    params = kinds.init_members(spec.module, spec.kind, k_init, spec.obs_dim, spec.n_members)
    if spec.bootstrap:
        samples = jax.random.randint(k_boot, (spec.n_members, spec.n_train), 0, spec.n_train)
    else:
        samples = jnp.broadcast_to(jnp.arange(spec.n_train), (spec.n_members, spec.n_train))
    return TrainState(
        params=params,
        opt_state=jax.vmap(spec.optimizer().init)(params),
        key=k_run,
        samples=samples.astype(jnp.int32),
        best_params=params,
        best_loss=jnp.asarray(jnp.inf, jnp.float32),
        best_epoch=jnp.asarray(0, jnp.int32),
    )


def keep_best(state: Any, params: Any, opt_state: Any, loss: jax.Array, **marks: Any) -> Any:
    """``state`` (a struct with ``params``, ``opt_state``, ``best_params`` and ``best_loss``)
    moved on to ``params`` and ``opt_state``; where ``loss`` beats ``best_loss`` the best
    params and loss become these, and each ``marks`` field (``best_epoch=e + 1``) its value.
    Traceable (``jnp.where``), so it runs inside a jitted scan."""
    better = loss < state.best_loss
    return state.replace(
        params=params,
        opt_state=opt_state,
        best_params=jax.tree.map(
            lambda new, old: jnp.where(better, new, old), params, state.best_params
        ),
        best_loss=jnp.where(better, loss, state.best_loss),
        **{k: jnp.where(better, v, getattr(state, k)) for k, v in marks.items()},
    )


def _train_epoch(
    spec: LoopSpec, state: TrainState, data: dict[str, jax.Array], key: jax.Array
) -> tuple[Any, Any, jax.Array]:
    """One pass over the training split; returns (params, opt_state, (K,) mean train loss)."""
    tx = spec.optimizer()
    k_perm, k_drop = jax.random.split(key)
    idx, w = jax.vmap(lambda k, s: _batches(k, s, spec.n_batches, spec.batch_size))(
        jax.random.split(k_perm, spec.n_members), state.samples
    )
    drop_bits = jax.random.bits(k_drop, (spec.n_members, spec.n_batches, 4), jnp.uint32)
    drop = jax.random.wrap_key_data(drop_bits, impl="rbg")

    def member_step(params: Any, opt_state: Any, i: jax.Array, wi: jax.Array, rng: jax.Array):
        obs, action, mask = _gather(data, "train", i, wi)
        grad_fn = jax.value_and_grad(
            lambda p: member_loss(spec, p, obs, action, mask, rng, True), has_aux=True
        )
        (loss, weight), grads = grad_fn(params)
        updates, opt_state = tx.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, loss * weight, weight

    def member_epoch(member: tuple[Any, ...]) -> tuple[Any, ...]:
        def step(carry: tuple[Any, Any], xs: tuple[jax.Array, ...]):
            params, opt_state, lsum, wsum = member_step(*carry, *xs)
            return (params, opt_state), (lsum, wsum)

        params, opt_state, xs = member[0], member[1], member[2:]
        (params, opt_state), (lsum, wsum) = jax.lax.scan(step, (params, opt_state), xs)
        return params, opt_state, jnp.sum(lsum) / jnp.maximum(jnp.sum(wsum), 1.0)

    # members one after another, each over all its minibatches (see the module docstring)
    return jax.lax.map(member_epoch, (state.params, state.opt_state, idx, w, drop))


def _validate(spec: LoopSpec, params: Any, data: dict[str, jax.Array]) -> jax.Array:
    """(K,) mean validation loss of each member (no dropout)."""
    total = spec.n_val_batches * spec.batch_size
    idx = jnp.resize(jnp.arange(spec.n_val), (total,)).reshape(-1, spec.batch_size)
    w = (jnp.arange(total) < spec.n_val).astype(jnp.float32).reshape(-1, spec.batch_size)
    rng = jax.random.key(0)

    def step(acc: tuple[jax.Array, jax.Array], xs: tuple[jax.Array, jax.Array]):
        obs, action, mask = _gather(data, "val", *xs)
        loss, weight = jax.vmap(lambda p: member_loss(spec, p, obs, action, mask, rng, False))(
            params
        )
        return (acc[0] + loss * weight, acc[1] + weight), None

    zero = jnp.zeros(spec.n_members)
    (lsum, wsum), _ = jax.lax.scan(step, (zero, zero), (idx, w))
    return lsum / jnp.maximum(wsum, 1.0)


def run_epochs(
    spec: LoopSpec,
    state: TrainState,
    data: dict[str, jax.Array],
    first_epoch: jax.Array,
    n_epochs: int,
) -> tuple[TrainState, tuple[jax.Array, jax.Array]]:
    """Run ``n_epochs`` epochs of ONE seed, numbered from ``first_epoch`` (0-based).

    Returns:
      (new state, (train loss (n, K), val loss (n, K))); val loss is NaN without a split.
    """

    def epoch(state: TrainState, e: jax.Array):
        params, opt_state, train_loss = _train_epoch(
            spec, state, data, jax.random.fold_in(state.key, e)
        )
        if spec.n_val > 0:
            val_loss = _validate(spec, params, data)
            score = jnp.mean(val_loss)
        else:
            val_loss = jnp.full((spec.n_members,), jnp.nan)
            score = jnp.mean(train_loss)
        state = keep_best(state, params, opt_state, score, best_epoch=e + 1)
        return state, (train_loss, val_loss)

    return jax.lax.scan(epoch, state, first_epoch + jnp.arange(n_epochs))


@functools.lru_cache(maxsize=8)
def make_chunk_fn(spec: LoopSpec, n_epochs: int) -> Callable[..., Any]:
    """Jitted ``fn(states, data, first_epoch) -> (states, (train (S, n, K), val (S, n, K)))``
    over a leading seed axis S. Cached: one compile per (spec, n_epochs, S), reused per chunk
    and across runs of the same shapes in a process."""

    def one(state: TrainState, data: dict[str, jax.Array], first: jax.Array):
        return run_epochs(spec, state, data, first, n_epochs)

    def chunk(states: TrainState, data: dict[str, jax.Array], first: jax.Array):
        if jax.tree.leaves(states)[0].shape[0] == 1:  # one seed: no extra batch dimension
            state, out = one(jax.tree.map(lambda x: x[0], states), data, first)
            return jax.tree.map(lambda x: x[None], (state, out))
        return jax.vmap(one, in_axes=(0, None, None))(states, data, first)

    return jax.jit(chunk, donate_argnums=0)


def init_states(spec: LoopSpec, seeds: tuple[int, ...]) -> TrainState:
    """Initial states of several seeds, stacked on a leading seed axis.

    Seeds are initialised one after another by one jitted function: vmapping the LSTM's
    orthogonal initialiser (a batched QR) over seeds AND members deadlocks XLA:CPU (jax 0.10).
    """
    init = jax.jit(lambda k: init_state(spec, jax.random.wrap_key_data(k)))
    states = [init(jax.random.key_data(jax.random.key(s))) for s in seeds]
    return jax.tree.map(lambda *xs: jnp.stack(xs), *states)
