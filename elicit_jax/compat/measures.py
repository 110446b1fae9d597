"""Compatibility measures for ONE state-action pair: likelihood error, novelty, compatibility.

Definitions (Gandhi et al. 2022; ``docs/method.md``). For members ``π_1..π_K`` with
predictions ``p`` of shape ``(K, A)`` at state ``s`` and the demonstrated action ``a`` ``(A,)``:

* likelihood error ``ℓ``:
    ``ensemble-mean`` (paper, default): mean over dims of ``(π̄(s) − a)²``;
    ``member-average`` (original simulation code): mean over members of the mean over dims of
    ``(clip(π_k(s)) − clip(a))²``, clipping to ``±clip``;
* novelty ``ν``: mean over dims of the standard deviation across members (``ddof=0``, the
  population std of the paper's text; ``ddof=1``, the sample std the original code uses). A
  model with its own spread (MDN) uses the mean over dims of that spread instead;
* compatibility ``M = 1 − min(ℓ/λ, 1)`` if ``ν < η`` else ``1``; a pair is *incompatible* when
  its likelihood error *exceeds* λ in a familiar state: ``ℓ > λ`` and ``ν < η``
  (:func:`is_incompatible`, strict as in the paper's text and the original code; at the tie
  ``ℓ = λ`` M is 0 but the pair is not flagged).

Every function here handles one example; callers ``jax.vmap`` them.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal

import jax.numpy as jnp
from flax import struct

from elicit_jax.errors import ElicitError

Likelihood = Literal["ensemble-mean", "member-average"]
LIKELIHOODS: tuple[str, ...] = ("ensemble-mean", "member-average")

# Paper thresholds (averaged over action dims): name -> (lambda, eta).
PRESETS: dict[str, tuple[float, float]] = {
    "square-nut": (0.4, 0.05),
    "round-nut": (0.35, 0.05),
    "hammer-drawer": (0.35, 0.06),
}


def check_thresholds(lambda_: float, eta: float, source: str | None = None) -> tuple[float, float]:
    """The one validation of (λ, η) every command applies: both finite and > 0.

    Returns:
      ``(float(lambda_), float(eta))``.

    Raises:
      ElicitError: naming ``source`` (a thresholds file) when given.
    """
    try:
        lam, et = float(lambda_), float(eta)
    except (TypeError, ValueError) as e:
        raise ElicitError(f"thresholds must be numbers, got lambda={lambda_!r}, eta={eta!r}") from e
    for name, v in (("lambda", lam), ("eta", et)):
        if not (math.isfinite(v) and v > 0):
            raise ElicitError(f"{name} must be a finite number > 0, got {v:g}", source)
    return lam, et


def check_accept_fraction(fraction: float) -> float:
    """The one validation of the accept/reject rule's fraction: in [0, 1)."""
    f = float(fraction)
    if not 0 <= f < 1:
        raise ElicitError(f"accept fraction must be in [0, 1), got {f:g}")
    return f


def is_incompatible(ell: Any, nu: Any, lambda_: Any, eta: Any) -> Any:
    """The incompatible test on scalars or arrays (NumPy or JAX): ``ℓ > λ`` and ``ν < η``."""
    return (ell > lambda_) & (nu < eta)


@dataclasses.dataclass(frozen=True)
class ScoreConfig:
    """How pairs are scored and judged.

    Attributes:
      likelihood: ``ensemble-mean`` (paper) or ``member-average`` (original sim code).
      ddof: delta degrees of freedom of the across-member std (0 paper, 1 original code).
      lambda_: likelihood-error threshold λ.
      eta: novelty threshold η.
      accept_fraction: a demonstration is rejected when its number of incompatible pairs
        exceeds this fraction of its length (paper: 5%).
      chunk_size: pairs per jitted scoring call (the last chunk is padded).
      clip: action bound used by ``member-average`` clipping.
    """

    likelihood: Likelihood = "ensemble-mean"
    ddof: int = 0
    lambda_: float = PRESETS["square-nut"][0]
    eta: float = PRESETS["square-nut"][1]
    accept_fraction: float = 0.05
    chunk_size: int = 4096
    clip: float = 1.0

    def __post_init__(self) -> None:
        if self.likelihood not in LIKELIHOODS:
            raise ElicitError(
                f"unknown likelihood '{self.likelihood}' (choose {', '.join(LIKELIHOODS)})"
            )
        if self.ddof not in (0, 1):
            raise ElicitError(f"ddof must be 0 or 1, got {self.ddof}")
        check_thresholds(self.lambda_, self.eta)
        check_accept_fraction(self.accept_fraction)
        if self.chunk_size < 1:
            raise ElicitError(f"chunk size must be >= 1, got {self.chunk_size}")

    @classmethod
    def from_preset(cls, name: str, **overrides: object) -> ScoreConfig:
        """Config with the paper's thresholds for task ``name`` (see :data:`PRESETS`)."""
        if name not in PRESETS:
            raise ElicitError(f"unknown preset '{name}' (choose {', '.join(sorted(PRESETS))})")
        lam, eta = PRESETS[name]
        return cls(**{"lambda_": lam, "eta": eta, **overrides})  # type: ignore[arg-type]


@struct.dataclass
class PairScores:
    """Scores of one pair (or, after vmap, arrays of them).

    Attributes:
      likelihood: ℓ, scalar.
      novelty: ν, scalar.
      compatibility: M in [0, 1], scalar.
      incompatible: ``ℓ > λ`` and ``ν < η``, scalar bool.
      mean: ensemble-mean prediction π̄(s), ``(A,)``.
    """

    likelihood: jnp.ndarray
    novelty: jnp.ndarray
    compatibility: jnp.ndarray
    incompatible: jnp.ndarray
    mean: jnp.ndarray


def likelihood_error(
    members: jnp.ndarray, action: jnp.ndarray, kind: Likelihood = "ensemble-mean", clip: float = 1.0
) -> jnp.ndarray:
    """Likelihood error ℓ of one pair.

    Args:
      members: (K, A) member predictions π_k(s).
      action: (A,) demonstrated action.
      kind: ``ensemble-mean`` or ``member-average`` (see module docstring).
      clip: bound for the ``member-average`` clipping.

    Returns:
      scalar ℓ.
    """
    if kind == "ensemble-mean":
        return jnp.mean((jnp.mean(members, axis=0) - action) ** 2)
    if kind == "member-average":
        diff = jnp.clip(members, -clip, clip) - jnp.clip(action, -clip, clip)[None, :]
        return jnp.mean(jnp.mean(diff**2, axis=-1))
    raise ElicitError(f"unknown likelihood '{kind}'")


def novelty(members: jnp.ndarray, ddof: int = 0) -> jnp.ndarray:
    """Novelty ν of one state: mean over dims of the across-member std.

    Args:
      members: (K, A) member predictions.
      ddof: 0 (population std) or 1 (sample std; needs K > 1).

    Returns:
      scalar ν.
    """
    return jnp.mean(jnp.std(members, axis=0, ddof=ddof))


def compatibility(
    likelihood: jnp.ndarray, novelty_: jnp.ndarray, lambda_: float, eta: float
) -> jnp.ndarray:
    """``M = 1 − min(ℓ/λ, 1)`` if ``ν < η`` else ``1``; scalar in [0, 1]."""
    m = 1.0 - jnp.minimum(likelihood / lambda_, 1.0)
    return jnp.where(novelty_ < eta, m, 1.0)


def score_pair(
    members: jnp.ndarray,
    action: jnp.ndarray,
    lambda_: jnp.ndarray,
    eta: jnp.ndarray,
    config: ScoreConfig,
    spread: jnp.ndarray | None = None,
) -> PairScores:
    """All scores of one pair.

    Args:
      members: (K, A) member predictions (MDN: K = 1, its low-noise action).
      action: (A,) demonstrated action.
      lambda_: scalar λ (an argument, so changing it does not recompile).
      eta: scalar η.
      config: likelihood kind, ddof and clip are read from it.
      spread: (A,) the model's own per-dim spread (MDN); replaces the across-member std.

    Returns:
      :class:`PairScores` of this pair.
    """
    ell = likelihood_error(members, action, config.likelihood, config.clip)
    nu = jnp.mean(spread) if spread is not None else novelty(members, config.ddof)
    m = compatibility(ell, nu, lambda_, eta)
    return PairScores(ell, nu, m, is_incompatible(ell, nu, lambda_, eta), jnp.mean(members, axis=0))


def rejects(n_incompatible: int, length: int, accept_fraction: float = 0.05) -> bool:
    """The accept/reject rule: reject when incompatible pairs exceed ``fraction × length``."""
    return bool(n_incompatible > accept_fraction * length)
