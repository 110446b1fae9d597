"""Flax modules of ONE ensemble member, and pure functions applying them to stacked params.

Every model maps *normalised* observations to actions in [-1, 1]. An ensemble is one
parameter pytree whose leaves carry a leading member axis ``K``
(:func:`elicit_jax.policy.kinds.init_members` builds it) and
:class:`~elicit_jax.policy.base.Policy` runs all members in a single call. Which module a model
kind uses, and how it is initialised and trained, is its entry in
:mod:`elicit_jax.policy.kinds`.

Architectures (paper defaults, ``docs/method.md``):
  * ``mlp``: ``hidden`` Dense layers, each followed by LayerNorm and ReLU, dropout between
    hidden layers (``dropout_last``: after every hidden layer, before the head too, as the
    original code does), a Dense head and ``tanh``.
  * ``mdn``: the same trunk; heads for ``n_components`` mixture logits, tanh-bounded means and
    softplus scales plus a floor ``min_std`` (default ``MDN_MIN_STD``) per action dim.
  * ``lstm``: stacked LSTM cells of sizes ``hidden``, a Dense head and ``tanh``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp

from elicit_jax.policy.dropout import BitDropout

MDN_MIN_STD = 1e-4  # the MDN's default floor on component stds (paper profile)
LAYER_NORM_EPS = 1e-6  # Flax's default; PyTorch (the original code) uses 1e-5
Params = Any
LSTMCarry = tuple[tuple[jax.Array, jax.Array], ...]


class Trunk(nn.Module):
    """Dense -> LayerNorm -> ReLU per hidden layer, dropout between hidden layers
    (:class:`~elicit_jax.policy.dropout.BitDropout`), and after the last one too when
    ``dropout_last``."""

    hidden: Sequence[int]
    dropout: float
    layer_norm_eps: float = LAYER_NORM_EPS
    dropout_last: bool = False

    @nn.compact
    def __call__(self, x: jax.Array, train: bool) -> jax.Array:
        for i, size in enumerate(self.hidden):
            if i > 0 and self.dropout > 0.0:
                x = BitDropout(self.dropout)(x, deterministic=not train)
            x = nn.relu(nn.LayerNorm(epsilon=self.layer_norm_eps)(nn.Dense(size)(x)))
        if self.dropout_last and self.dropout > 0.0:
            x = BitDropout(self.dropout)(x, deterministic=not train)
        return x


class MLPMember(nn.Module):
    """One MLP member: obs ``(..., O)`` -> action ``(..., A)`` in [-1, 1]."""

    hidden: Sequence[int]
    action_dim: int
    dropout: float
    layer_norm_eps: float = LAYER_NORM_EPS
    dropout_last: bool = False

    @nn.compact
    def __call__(self, x: jax.Array, train: bool = False) -> jax.Array:
        x = Trunk(self.hidden, self.dropout, self.layer_norm_eps, self.dropout_last)(x, train)
        return jnp.tanh(nn.Dense(self.action_dim)(x))


class MDNMember(nn.Module):
    """One mixture density network: obs ``(..., O)`` -> (logits ``(..., C)``,
    means ``(..., C, A)`` in [-1, 1], stds ``(..., C, A)``)."""

    hidden: Sequence[int]
    action_dim: int
    dropout: float
    n_components: int
    layer_norm_eps: float = LAYER_NORM_EPS
    dropout_last: bool = False
    min_std: float = MDN_MIN_STD

    @nn.compact
    def __call__(self, x: jax.Array, train: bool = False) -> tuple[jax.Array, ...]:
        x = Trunk(self.hidden, self.dropout, self.layer_norm_eps, self.dropout_last)(x, train)
        c, a = self.n_components, self.action_dim
        logits = nn.Dense(c, name="logits")(x)
        means = jnp.tanh(nn.Dense(c * a, name="means")(x)).reshape(*x.shape[:-1], c, a)
        raw = nn.Dense(c * a, name="scales")(x).reshape(*x.shape[:-1], c, a)
        return logits, means, nn.softplus(raw) + self.min_std


class LSTMStep(nn.Module):
    """One step of stacked LSTM cells: (carry, obs ``(B, O)``) -> (carry, action ``(B, A)``)."""

    hidden: Sequence[int]
    action_dim: int

    @nn.compact
    def __call__(self, carry: LSTMCarry, x: jax.Array) -> tuple[LSTMCarry, jax.Array]:
        new = []
        for i, size in enumerate(self.hidden):
            c, x = nn.OptimizedLSTMCell(size, name=f"lstm_{i}")(carry[i], x)
            new.append(c)
        return tuple(new), jnp.tanh(nn.Dense(self.action_dim, name="head")(x))


def lstm_zero_carry(hidden: Sequence[int], batch: int) -> LSTMCarry:
    """Zero LSTM state for ``batch`` rows: per layer ``(c (B, H), h (B, H))``."""
    return tuple((jnp.zeros((batch, h)), jnp.zeros((batch, h))) for h in hidden)


def lstm_sequence(module: nn.Module, params: Params, obs: jax.Array, reset: jax.Array) -> jax.Array:
    """Run one member over a batch of sequences.

    Args:
      module: an :class:`LSTMStep`.
      params: one member's params.
      obs: (L, B, O) normalised observations, time first.
      reset: (L,) bool; the state is zeroed before steps where it is true.

    Returns:
      (L, B, A) actions.
    """
    zero = lstm_zero_carry(module.hidden, obs.shape[1])

    def step(carry: LSTMCarry, inp: tuple[jax.Array, jax.Array]) -> tuple[LSTMCarry, jax.Array]:
        x, r = inp
        carry = jax.tree.map(lambda z, c: jnp.where(r, z, c), zero, carry)
        return module.apply({"params": params}, carry, x)

    _, actions = jax.lax.scan(step, zero, (obs, reset))
    return actions


def mdn_mode(logits: jax.Array, means: jax.Array) -> jax.Array:
    """Mean of the most likely component: ``(..., C)``, ``(..., C, A)`` -> ``(..., A)``.

    This is the deterministic limit of the paper's "low-noise" evaluation (component scales set
    to 1e-4): sampling then returns the chosen component's mean up to 1e-4, and we choose the
    component by its mixture weight instead of sampling it.
    """
    idx = jnp.argmax(logits, axis=-1)
    return jnp.take_along_axis(means, idx[..., None, None], axis=-2)[..., 0, :]


def mdn_std(logits: jax.Array, means: jax.Array, stds: jax.Array) -> jax.Array:
    """Per-dim mixture std: ``(..., C)``, ``(..., C, A)``, ``(..., C, A)`` -> ``(..., A)``."""
    w = jax.nn.softmax(logits, axis=-1)[..., None]
    mean = jnp.sum(w * means, axis=-2)
    second = jnp.sum(w * (stds**2 + means**2), axis=-2)
    return jnp.sqrt(jnp.maximum(second - mean**2, 0.0))


def mdn_log_likelihood(
    logits: jax.Array, means: jax.Array, stds: jax.Array, action: jax.Array
) -> jax.Array:
    """Log-density of ``action (..., A)`` under the mixture (diagonal Gaussians) -> ``(...)``."""
    z = (action[..., None, :] - means) / stds
    comp = jnp.sum(-0.5 * z**2 - jnp.log(stds) - 0.5 * jnp.log(2.0 * jnp.pi), axis=-1)
    return jax.scipy.special.logsumexp(jax.nn.log_softmax(logits, axis=-1) + comp, axis=-1)
