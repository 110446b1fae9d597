"""The :class:`Policy` pytree: stacked member params, normalisation stats, static spec.

A ``Policy`` is a ``flax.struct.dataclass``; its arrays are pytree leaves and its spec fields
are static, so one jitted function taking a ``Policy`` compiles once per architecture and
serves every checkpoint of it.

Example::

    policy = load_policy("runs/base/seed0").policy
    preds = policy.members(obs)        # (K, B, A)
    carry = policy.init_carry(B)
    carry, action = policy.act(carry, obs)   # (B, A), ensemble mean in [-1, 1]
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from elicit_jax.policy import kinds, models

STD_FLOOR = 1e-6
MEMBER_LOOP_ROWS = 512  # batches this large run the members one after another


@struct.dataclass
class Policy:
    """A trained (or freshly initialised) ensemble policy.

    Attributes:
      params: member params; every leaf has a leading member axis ``n_members``.
      obs_mean: (obs_dim,) mean of the training observations.
      obs_std: (obs_dim,) their std, with near-constant dims set to 1.
      kind: ``mlp``, ``mdn`` or ``lstm``.
      obs_dim: observation size O.
      action_dim: action size A.
      n_members: ensemble size K (1 for the MDN baseline by default).
      hidden: hidden layer sizes.
      dropout: dropout rate used in training (inactive here).
      n_components: mixture components (MDN only).
      reset_every: LSTM only: the recurrent state is zeroed every this many steps (the training
        window length), as in training; 0 never resets.
      obs_fields: names of the observation fields, in order.
      layer_norm_eps: epsilon of the trunk's LayerNorm (Flax's 1e-6; the original code's
        PyTorch 1e-5).
      dropout_last: dropout also after the last hidden layer (the original code), not only
        between hidden layers (the paper).
      mdn_min_std: MDN only: floor on the mixture components' stds.
      action_std: (A,) std of the training actions per dim (action scaling), or None for
        checkpoints that predate it.
    """

    params: Any
    obs_mean: jax.Array
    obs_std: jax.Array
    kind: str = struct.field(pytree_node=False)
    obs_dim: int = struct.field(pytree_node=False)
    action_dim: int = struct.field(pytree_node=False)
    n_members: int = struct.field(pytree_node=False)
    hidden: tuple[int, ...] = struct.field(pytree_node=False)
    dropout: float = struct.field(pytree_node=False, default=0.0)
    n_components: int = struct.field(pytree_node=False, default=2)
    reset_every: int = struct.field(pytree_node=False, default=0)
    obs_fields: tuple[str, ...] = struct.field(pytree_node=False, default=())
    layer_norm_eps: float = struct.field(pytree_node=False, default=models.LAYER_NORM_EPS)
    dropout_last: bool = struct.field(pytree_node=False, default=False)
    mdn_min_std: float = struct.field(pytree_node=False, default=models.MDN_MIN_STD)
    action_std: Any = None

    @property
    def entry(self) -> kinds.ModelKind:
        """The registry entry of the policy's kind (:mod:`elicit_jax.policy.kinds`)."""
        return kinds.model_kind(self.kind)

    @property
    def module(self) -> Any:
        """The Flax module of one member."""
        return kinds.make_module(
            self.kind,
            self.hidden,
            self.action_dim,
            self.dropout,
            self.n_components,
            layer_norm_eps=self.layer_norm_eps,
            dropout_last=self.dropout_last,
            mdn_min_std=self.mdn_min_std,
        )

    def normalize(self, obs: jax.Array) -> jax.Array:
        """Raw obs ``(..., O)`` -> normalised obs ``(..., O)``."""
        if obs.shape[-1] != self.obs_dim:
            raise ValueError(f"policy expects obs of size {self.obs_dim}, got {obs.shape[-1]}")
        return (obs - self.obs_mean) / self.obs_std

    def members(self, obs: jax.Array) -> jax.Array:
        """Deterministic member predictions.

        Args:
          obs: (B, O) raw observations. For ``lstm`` the B rows are ONE sequence, run from the
            zero state (reset every ``reset_every`` steps).

        Returns:
          (K, B, A) actions in [-1, 1]; for ``mdn`` the low-noise action (mean of the most
          likely component).
        """
        x = self.normalize(obs)
        module = self.module
        entry = self.entry
        if not entry.recurrent:
            return self.each_member(lambda p: entry.predict(module, p, x), x.shape[0])
        reset = _reset_mask(x.shape[0], self.reset_every)
        out = jax.vmap(lambda p: models.lstm_sequence(module, p, x[:, None, :], reset))(self.params)
        return out[:, :, 0, :]

    def sample_members(self, obs: jax.Array, keys: jax.Array, n: int) -> jax.Array:
        """Member predictions with dropout active (MC dropout), ``n`` passes per member.

        Args:
          obs: (B, O) raw observations.
          keys: (B,) PRNG keys, one per row: masks depend on the row's key only, so a row
            scores the same whatever batch it is in.
          n: passes per member.

        Returns:
          (K * n, B, A) predictions: member k's passes are rows ``k * n .. k * n + n - 1``.
        """
        if not self.entry.mc_dropout:
            raise ValueError(f"MC-dropout scoring needs an MLP ensemble, not {self.kind}")
        x = self.normalize(obs)
        module = self.module

        def one(p: Any, member: jax.Array, xr: jax.Array, key: jax.Array) -> jax.Array:
            def sample(i: jax.Array) -> jax.Array:
                k = jax.random.fold_in(jax.random.fold_in(key, member), i)
                return module.apply({"params": p}, xr[None], True, rngs={"dropout": k})[0]

            return jax.vmap(sample)(jnp.arange(n))  # (n, A)

        rows = jax.vmap(one, in_axes=(None, None, 0, 0))  # over rows -> (B, n, A)
        out = jax.vmap(rows, in_axes=(0, 0, None, None))(
            self.params, jnp.arange(self.n_members), x, keys
        )  # (K, B, n, A)
        return jnp.swapaxes(out, 1, 2).reshape(self.n_members * n, x.shape[0], -1)

    def spread(self, obs: jax.Array) -> jax.Array | None:
        """Per-dim spread of the model's own predictive distribution, ``(B, A)``, or ``None``.

        MDN: the mixture's standard deviation (averaged over members if K > 1). Ensembles
        without their own uncertainty return ``None`` (use the spread across members).
        """
        spread = self.entry.spread
        if spread is None:
            return None
        x = self.normalize(obs)
        module = self.module
        std = self.each_member(lambda p: spread(module, p, x), x.shape[0])
        return jnp.mean(std, axis=0)

    def each_member(self, fn: Any, rows: int) -> Any:
        """``fn(params_k)`` of every member, stacked on a leading axis K.

        Batches of at least :data:`MEMBER_LOOP_ROWS` rows run the members one after another
        (``lax.map``), smaller ones all at once (``vmap``). On XLA:CPU the vmapped layout
        turns a large batch into member-batched matmuls fused with the LayerNorms into one
        library call, which ran at about half the plain matmul's speed (4096 rows, paper
        sizes); one member at a time keeps every matmul 2-D and near the matmul's speed. A
        few rows keep ``vmap``: ``lax.map`` copies each member's weights out of the stack,
        which costs more than the rows' arithmetic there (a single row: ~3x slower).
        """
        if rows >= MEMBER_LOOP_ROWS:
            return jax.lax.map(fn, self.params)
        return jax.vmap(fn)(self.params)

    def init_carry(self, batch: int) -> Any:
        """Recurrent state for ``batch`` parallel rollouts: ``()`` for feed-forward models;
        for ``lstm`` ``(step (), per-layer (c, h) with shape (K, B, H))``."""
        if not self.entry.recurrent:
            return ()
        zero = models.lstm_zero_carry(self.hidden, batch)
        stacked = jax.tree.map(lambda z: jnp.broadcast_to(z, (self.n_members, *z.shape)), zero)
        return (jnp.zeros((), jnp.int32), stacked)

    def act(self, carry: Any, obs: jax.Array) -> tuple[Any, jax.Array]:
        """One control step for B parallel environments.

        Args:
          carry: from :meth:`init_carry` or the previous :meth:`act`.
          obs: (B, O) raw observations.

        Returns:
          (new carry, (B, A) ensemble-mean action in [-1, 1]).
        """
        if not self.entry.recurrent:
            return carry, jnp.mean(self.members(obs), axis=0)
        x = self.normalize(obs)
        step, state = carry
        module = self.module
        if self.reset_every > 0:
            zero = self.init_carry(obs.shape[0])[1]
            reset = (step % self.reset_every) == 0
            state = jax.tree.map(lambda z, c: jnp.where(reset, z, c), zero, state)
        state, actions = jax.vmap(lambda p, c: module.apply({"params": p}, c, x))(
            self.params, state
        )
        return (step + 1, state), jnp.mean(actions, axis=0)


def _reset_mask(length: int, every: int) -> jax.Array:
    """(length,) bool: true at steps where the LSTM state is zeroed (step 0 always)."""
    t = jnp.arange(length)
    return t == 0 if every <= 0 else (t % every) == 0


def normalization_stats(obs: Any) -> tuple[Any, Any]:
    """Mean and std ``(O,)`` of training observations ``(N, O)``; stds below 1e-6 become 1."""
    import numpy as np

    obs = np.asarray(obs, np.float64)
    mean = obs.mean(axis=0)
    std = obs.std(axis=0)
    std = np.where(std < STD_FLOOR, 1.0, std)
    return mean.astype(np.float32), std.astype(np.float32)


def init_policy(
    key: jax.Array,
    *,
    kind: str,
    obs_dim: int,
    action_dim: int,
    n_members: int,
    hidden: tuple[int, ...],
    dropout: float = 0.0,
    n_components: int = 2,
    reset_every: int = 0,
    obs_fields: tuple[str, ...] = (),
    obs_mean: Any = None,
    obs_std: Any = None,
    layer_norm_eps: float = models.LAYER_NORM_EPS,
    dropout_last: bool = False,
    mdn_min_std: float = models.MDN_MIN_STD,
) -> Policy:
    """A freshly initialised policy (identity normalisation unless stats are given)."""
    module = kinds.make_module(
        kind,
        hidden,
        action_dim,
        dropout,
        n_components,
        layer_norm_eps=layer_norm_eps,
        dropout_last=dropout_last,
        mdn_min_std=mdn_min_std,
    )
    params = kinds.init_members(module, kind, key, obs_dim, n_members)
    return Policy(
        params=params,
        obs_mean=jnp.zeros(obs_dim) if obs_mean is None else jnp.asarray(obs_mean),
        obs_std=jnp.ones(obs_dim) if obs_std is None else jnp.asarray(obs_std),
        kind=kind,
        obs_dim=obs_dim,
        action_dim=action_dim,
        n_members=n_members,
        hidden=tuple(int(h) for h in hidden),
        dropout=float(dropout),
        n_components=int(n_components),
        reset_every=int(reset_every),
        obs_fields=tuple(obs_fields),
        layer_norm_eps=float(layer_norm_eps),
        dropout_last=bool(dropout_last),
        mdn_min_std=float(mdn_min_std),
    )


@functools.cache
def jitted_act() -> Any:
    """The jitted ``act(policy, carry, obs) -> (carry, action)``, built once per process and
    shared by every rollout backend."""
    return jax.jit(lambda policy, carry, obs: policy.act(carry, obs))
