"""The compiled scorer of state-action pairs: its numeric inputs and its jitted functions.

:func:`score_rows` scores a chunk of independent pairs (feed-forward policies) and
:func:`score_sequences` a group of padded episodes (recurrent ones), each the per-pair
:func:`~elicit_jax.compat.measures.score_pair` vmapped over its rows. The numbers of a run
(λ, η, clipping bounds, action weights, the MC-dropout seed) are a :class:`ScoreInputs`
argument, not compile-time constants, and only :func:`static_config`'s fields shape the
compile: the batch scorer (:mod:`elicit_jax.compat.score`) and the live scorer
(:mod:`elicit_jax.elicit.live`) call these same functions, so a pair scores the same in both.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import jax
import numpy as np
from flax import struct

from elicit_jax.compat.measures import ScoreConfig, score_pair
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.policy.base import Policy


@struct.dataclass
class ScoreInputs:
    """Numbers of a scoring call that are arguments, not compile-time constants.

    Attributes:
      lam: λ; eta: η (scalars).
      low: (A,) lower clipping bound of ``member-average``; high: (A,) upper bound.
      weight: (A,) action scaling (1/std; a dim constant in training: 1/median std of the
        others), or None (paper).
      seed: MC-dropout seed (int32 scalar).
    """

    lam: Any
    eta: Any
    low: Any
    high: Any
    weight: Any
    seed: Any


STILL_STD = 1e-6
"""An action dim whose training actions' std is below this never moved (:func:`still_dims`)."""


def static_config(config: ScoreConfig) -> ScoreConfig:
    """The part of a config that shapes the compiled function (numbers are arguments).

    Args:
      config: the full score config.

    Returns:
      A config with only the fields :func:`score_rows` compiles on, so configs differing in
      λ, η or chunk size share one compile.
    """
    return ScoreConfig(
        thresholds=None,
        likelihood=config.likelihood,
        ddof=config.ddof,
        action_scale=config.action_scale,
        dropout_samples=config.dropout_samples,
    )


def _pair_fn(inputs: ScoreInputs, config: ScoreConfig) -> Callable[..., Any]:
    return functools.partial(
        score_pair,
        lambda_=inputs.lam,
        eta=inputs.eta,
        config=config,
        clip=(inputs.low, inputs.high),
        weight=inputs.weight,
    )


@functools.partial(jax.jit, static_argnames=("config",))
def score_rows(
    policy: Policy, obs: Any, action: Any, inputs: ScoreInputs, row0: Any, config: ScoreConfig
) -> Any:
    """Scores of a chunk of independent pairs (jitted; ``config`` is static).

    The batch scorer calls it per chunk and the live scorer per step, so both give the same
    numbers for the same pair.

    Args:
      policy: the trained policy (ensemble, MDN or dropout).
      obs: (C, O) observations.
      action: (C, A) actions.
      inputs: the numeric inputs from :func:`score_inputs` (λ, η, bounds, weight, seed).
      row0: the chunk's first row in the dataset: MC-dropout masks are keyed by the row,
        so they do not depend on the chunking.
      config: :func:`static_config` of the score config (one compile per shape).

    Returns:
      PairScores with leading axis C.
    """
    import jax.numpy as jnp

    if config.dropout_samples:
        base = jax.random.key(inputs.seed)
        rows = row0 + jnp.arange(obs.shape[0])
        keys = jax.vmap(lambda r: jax.random.fold_in(base, r))(rows)
        members = policy.sample_members(obs, keys, config.dropout_samples)  # (K*N, C, A)
        spread = None
    else:
        members = policy.members(obs)  # (K, C, A)
        spread = policy.spread(obs)  # (C, A) or None
    fn = _pair_fn(inputs, config)
    if spread is None:
        return jax.vmap(lambda m, a: fn(m, a), in_axes=(1, 0))(members, action)
    return jax.vmap(lambda m, a, s: fn(m, a, spread=s), in_axes=(1, 0, 0))(members, action, spread)


@functools.partial(jax.jit, static_argnames=("config",))
def score_sequences(
    policy: Policy, obs: Any, action: Any, inputs: ScoreInputs, config: ScoreConfig
):
    """Scores of G padded episodes from the zero state (recurrent policies; jitted, ``config``
    static). obs: (G, L, O), action: (G, L, A) -> PairScores (G, L)."""

    fn = _pair_fn(inputs, config)

    def one(o, a):
        members = policy.members(o)  # (K, L, A)
        return jax.vmap(lambda m, x: fn(m, x), in_axes=(1, 0))(members, a)

    return jax.vmap(one)(obs, action)


def still_dims(policy: Policy) -> list[int]:
    """The action dims the base policy's training actions never moved (std < 1e-6); empty
    when the checkpoint records no action std."""
    std = policy.action_std
    if std is None:
        return []
    return [int(i) for i in np.flatnonzero(np.asarray(std, np.float64) < STILL_STD)]


def action_weight(policy: Policy, config: ScoreConfig, source: str = "<policy>") -> Any:
    """Per-dim action scaling ``(A,)``: 1/std of the base policy's training actions; None for
    ``action_scale='none'``.

    A dim the training actions never moved (:func:`still_dims`) has no std to divide by; it is
    scored in units of the median std of the dims that moved (a floor on its scale), so an
    operator who drives it differs from one who does not, as much as a typical dim's worth.
    """
    if config.action_scale == "none":
        return None
    std = policy.action_std
    if std is None:
        raise ElicitError(
            "--action-scale std needs the training actions' std, which this checkpoint "
            "predates; retrain the base policy",
            source,
        )
    std = np.asarray(std, np.float64)
    moved = std >= STILL_STD
    if not moved.any():
        raise ElicitError("every action dim was constant in the training data", source)
    floor = float(np.median(std[moved]))
    return (1.0 / np.where(moved, std, floor)).astype(np.float32)


def score_inputs(
    policy: Policy, config: ScoreConfig, bounds: tuple[Any, Any] | None, source: str
) -> ScoreInputs:
    """The :class:`ScoreInputs` of a scoring run: thresholds, clipping bounds (``config.clip``,
    else the demonstrations' recorded ``bounds``, else ±1), action weights, dropout seed."""
    import jax.numpy as jnp

    if config.thresholds is None:
        raise ElicitError("scoring needs thresholds: the config holds none")
    a = int(policy.action_dim)
    if config.clip is not None:
        low, high = -config.clip, config.clip
    elif bounds is not None:
        low, high = bounds
    else:
        low, high = -1.0, 1.0
    weight = action_weight(policy, config, source)
    return ScoreInputs(
        lam=jnp.float32(config.thresholds.lam),
        eta=jnp.float32(config.thresholds.eta),
        low=jnp.broadcast_to(jnp.asarray(low, jnp.float32), (a,)),
        high=jnp.broadcast_to(jnp.asarray(high, jnp.float32), (a,)),
        weight=None if weight is None else jnp.asarray(weight),
        seed=jnp.int32(config.dropout_seed),
    )
