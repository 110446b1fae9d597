"""Compatibility measures for ONE state-action pair: likelihood error, novelty, compatibility.

Definitions (Gandhi et al. 2022; ``docs/method.md``). For members ``π_1..π_K`` with
predictions ``p`` of shape ``(K, A)`` at state ``s`` and the demonstrated action ``a`` ``(A,)``:

* likelihood error ``ℓ``:
    ``ensemble-mean`` (paper, default): mean over dims of ``(π̄(s) − a)²``;
    ``member-average`` (original simulation code): mean over members of the mean over dims of
    ``(clip(π_k(s)) − clip(a))²``, clipping to the demonstrations' recorded action bounds;
* novelty ``ν``: mean over dims of the standard deviation across members (``ddof=0``, the
  population std of the paper's text; ``ddof=1``, the sample std the original code uses). A
  model with its own spread (MDN) uses the mean over dims of that spread instead;
* compatibility ``M = 1 − min(ℓ/λ, 1)`` if ``ν < η`` else ``1``; a pair is *incompatible* when
  its likelihood error *exceeds* λ in a familiar state: ``ℓ > λ`` and ``ν < η``
  (:func:`is_incompatible`, strict as in the paper's text and the original code; at the tie
  ``ℓ = λ`` M is 0 but the pair is not flagged).

Options beyond the paper (default off): *action scaling* (``action_scale="std"``) divides each
action dim by the std of the base policy's training actions, so a ±1 gripper does not dominate
ℓ; a dim that was constant there is divided by the median std of the others instead (it has
none of its own), so driving it still counts; *MC-dropout scoring*
(``dropout_samples=N``) runs every member N times with its dropout active, the K·N predictions
forming the ensemble — the original code scored with dropout on.

Every function here handles one example; callers ``jax.vmap`` them.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Literal

import jax.numpy as jnp
from flax import struct

from elicit_jax.errors import ElicitError
from elicit_jax.sim.registry import preset_names, preset_table

if TYPE_CHECKING:
    from elicit_jax.compat.thresholds import Thresholds

Likelihood = Literal["ensemble-mean", "member-average"]
LIKELIHOODS: tuple[str, ...] = ("ensemble-mean", "member-average")
ACTION_SCALES: tuple[str, ...] = ("none", "std")

# Paper thresholds (averaged over action dims): name -> (lambda, eta). The numbers are the
# tasks' own data, in their registry entries (elicit_jax.sim.registry.TASKS).
PRESETS: Mapping[str, tuple[float, float]] = MappingProxyType(preset_table())
# Task names (ours and robosuite's / the original code's) -> preset.
TASK_PRESETS: Mapping[str, str] = MappingProxyType(preset_names())


def preset_for_task(task: str | None) -> str | None:
    """The paper preset of a task name (``NutAssemblyRound`` -> ``round-nut``), or None."""
    return TASK_PRESETS.get(str(task or "").strip().lower())


def check_accept_fraction(fraction: float) -> float:
    """The one validation of the accept/reject rule's fraction: in [0, 1)."""
    f = float(fraction)
    if not 0 <= f < 1:
        raise ElicitError(f"accept fraction must be in [0, 1), got {f:g}")
    return f


def is_incompatible(ell: Any, nu: Any, lambda_: Any, eta: Any) -> Any:
    """The incompatible test on scalars or arrays (NumPy or JAX): ``ℓ > λ`` and ``ν < η``."""
    return (ell > lambda_) & (nu < eta)


MAX_CHUNK_SIZE = 1 << 16
"""Most pairs one compiled scoring call takes (65,536; the default is 4,096). A chunk holds
each member's activations for every pair in it, members x pairs x widest layer float32
values: for the paper's ensemble (5 members of 1024 units) 20 KiB a pair, so 65,536 pairs
are 1.25 GiB per hidden layer, about what a laptop or a CI runner holds beside the policy,
and as many rows as the largest training minibatch (``MAX_BATCH_SIZE``) passes forward
through the same ensemble. The rows of a chunk are also the row batches the demonstrations
are read in. A larger chunk saves no time once a call fills the device, only memory."""
MAX_DROPOUT_SAMPLES = 1000
"""Most MC-dropout passes per member a :class:`ScoreConfig` accepts."""
MC_ROWS_BUDGET = 1 << 16
"""Member passes x rows scored in one compiled MC-dropout call at most: the chunk shrinks to
fit (the masks do not depend on the chunk; the scores change only by float32 rounding), so
many passes cost time, not memory."""


def check_chunk_size(chunk_size: Any) -> int:
    """The one validation of a scoring chunk size (``score --chunk-size``, a pipeline's
    ``[score] chunk_size``, a stored score config): an integer in 1..:data:`MAX_CHUNK_SIZE`.

    Raises:
      ElicitError: one line naming the setting, the allowed range and the value.
    """
    ok = isinstance(chunk_size, numbers.Integral) and not isinstance(chunk_size, bool)
    if not ok or not 1 <= chunk_size <= MAX_CHUNK_SIZE:
        raise ElicitError(
            f"chunk_size (--chunk-size) must be an integer in 1..{MAX_CHUNK_SIZE}, got "
            f"{chunk_size!r} (pairs per compiled scoring call; a larger chunk does not fit in "
            "memory beside an ensemble's activations)"
        )
    return int(chunk_size)


@dataclasses.dataclass(frozen=True, kw_only=True)
class ScoreConfig:
    """How pairs are scored and judged.

    Attributes:
      likelihood: ``ensemble-mean`` (paper) or ``member-average`` (original sim code).
      ddof: delta degrees of freedom of the across-member std (0 paper, 1 original code).
      thresholds: (λ, η) and where they came from; no default (every caller says which).
        None only in the static part of a config the compiled kernel keys on
        (:func:`~elicit_jax.compat.scorer.static_config`), which scores nothing by itself.
      accept_fraction: a demonstration is rejected when its number of incompatible pairs
        exceeds this fraction of its length (paper: 5%).
      chunk_size: pairs per jitted scoring call (the last chunk is padded), in
        1..:data:`MAX_CHUNK_SIZE` (:func:`check_chunk_size`).
      clip: ``member-average`` clipping bound ±clip; None (default): the scored demos'
        recorded action bounds, per dim.
      action_scale: ``none`` (paper) or ``std``: per-dim scaling by the base policy's training
        action std, constant dims by the median std of the others (see module docstring).
      dropout_samples: 0 (paper: deterministic members) or N > 0: MC-dropout scoring with N
        stochastic passes per member.
      dropout_seed: seed of the MC-dropout masks (scores are deterministic given it).
    """

    likelihood: Likelihood = "ensemble-mean"
    ddof: int = 0
    thresholds: Thresholds | None
    accept_fraction: float = 0.05
    chunk_size: int = 4096
    clip: float | None = None
    action_scale: str = "none"
    dropout_samples: int = 0
    dropout_seed: int = 0

    def __post_init__(self) -> None:
        if self.likelihood not in LIKELIHOODS:
            raise ElicitError(
                f"unknown likelihood '{self.likelihood}' (choose {', '.join(LIKELIHOODS)})"
            )
        if self.ddof not in (0, 1):
            raise ElicitError(f"ddof must be 0 or 1, got {self.ddof}")
        from elicit_jax.compat.thresholds import Thresholds

        if self.thresholds is not None and not isinstance(self.thresholds, Thresholds):
            raise ElicitError(f"thresholds must be a Thresholds value, got {self.thresholds!r}")
        check_accept_fraction(self.accept_fraction)
        check_chunk_size(self.chunk_size)
        if self.clip is not None and not (math.isfinite(self.clip) and self.clip > 0):
            raise ElicitError(f"clip must be a finite number > 0, got {self.clip}")
        if self.action_scale not in ACTION_SCALES:
            raise ElicitError(
                f"unknown action scale '{self.action_scale}' (choose {', '.join(ACTION_SCALES)})"
            )
        if not 0 <= self.dropout_samples <= MAX_DROPOUT_SAMPLES:
            raise ElicitError(
                f"dropout samples must be in 0..{MAX_DROPOUT_SAMPLES}, got "
                f"{self.dropout_samples} (passes per member; the spread of a few dozen is "
                "already stable)"
            )

    @classmethod
    def from_preset(cls, name: str, **overrides: object) -> ScoreConfig:
        """Config with the paper's thresholds for task ``name`` (see :data:`PRESETS`)."""
        if name not in PRESETS:
            raise ElicitError(f"unknown preset '{name}' (choose {', '.join(sorted(PRESETS))})")
        from elicit_jax.compat.thresholds import Thresholds

        chosen = Thresholds(*PRESETS[name], f"preset {name}")
        return cls(**{"thresholds": chosen, **overrides})  # type: ignore[arg-type]


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


def _bounds(clip: float | tuple[Any, Any]) -> tuple[Any, Any]:
    return (-clip, clip) if isinstance(clip, int | float) else clip


def _dim_mean(x: jnp.ndarray, weight: jnp.ndarray | None) -> jnp.ndarray:
    """Mean over the last (action) axis; with ``weight`` (A,), of ``x`` over dims whose weight
    is non-zero (the caller has already multiplied the weights in)."""
    if weight is None:
        return jnp.mean(x, axis=-1)
    return jnp.sum(x, axis=-1) / jnp.maximum(jnp.sum(weight != 0), 1)


def likelihood_error(
    members: jnp.ndarray,
    action: jnp.ndarray,
    kind: Likelihood = "ensemble-mean",
    clip: float | tuple[Any, Any] = 1.0,
    weight: jnp.ndarray | None = None,
) -> jnp.ndarray:
    """Likelihood error ℓ of one pair.

    Args:
      members: (K, A) member predictions π_k(s).
      action: (A,) demonstrated action.
      kind: ``ensemble-mean`` or ``member-average`` (see module docstring).
      clip: ``member-average`` clipping: ±clip, or per-dim ``(low (A,), high (A,))``.
      weight: (A,) per-dim scale (1/std; a dim constant in training: 1/median std of the
        others), or None for the plain mean.

    Returns:
      scalar ℓ.
    """
    w = 1.0 if weight is None else weight
    if kind == "ensemble-mean":
        return _dim_mean(((jnp.mean(members, axis=0) - action) * w) ** 2, weight)
    if kind == "member-average":
        low, high = _bounds(clip)
        diff = jnp.clip(members, low, high) - jnp.clip(action, low, high)[None, :]
        return jnp.mean(_dim_mean((diff * w) ** 2, weight))
    raise ElicitError(f"unknown likelihood '{kind}'")


def novelty(members: jnp.ndarray, ddof: int = 0, weight: jnp.ndarray | None = None) -> jnp.ndarray:
    """Novelty ν of one state: mean over dims of the across-member std.

    Args:
      members: (K, A) member predictions.
      ddof: 0 (population std) or 1 (sample std; needs K > 1).
      weight: (A,) per-dim scale, as in :func:`likelihood_error`.

    Returns:
      scalar ν.
    """
    std = jnp.std(members, axis=0, ddof=ddof)
    return _dim_mean(std if weight is None else std * weight, weight)


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
    clip: float | tuple[Any, Any] = 1.0,
    weight: jnp.ndarray | None = None,
) -> PairScores:
    """All scores of one pair.

    Args:
      members: (K, A) member predictions (MDN: K = 1, its low-noise action).
      action: (A,) demonstrated action.
      lambda_: scalar λ (an argument, so changing it does not recompile).
      eta: scalar η.
      config: likelihood kind and ddof are read from it.
      spread: (A,) the model's own per-dim spread (MDN); replaces the across-member std.
      clip: ``member-average`` clipping bounds (see :func:`likelihood_error`).
      weight: (A,) action scaling, or None (paper).

    Returns:
      :class:`PairScores` of this pair.
    """
    ell = likelihood_error(members, action, config.likelihood, clip, weight)
    if spread is not None:
        nu = _dim_mean(spread if weight is None else spread * weight, weight)
    else:
        nu = novelty(members, config.ddof, weight)
    m = compatibility(ell, nu, lambda_, eta)
    return PairScores(ell, nu, m, is_incompatible(ell, nu, lambda_, eta), jnp.mean(members, axis=0))


def rejects(n_incompatible: int, length: int, accept_fraction: float = 0.05) -> bool:
    """The accept/reject rule: reject when incompatible pairs exceed ``fraction × length``."""
    return bool(n_incompatible > accept_fraction * length)


def config_dict(config: ScoreConfig) -> dict[str, Any]:
    """JSON form of a score config: its settings, and its thresholds as ``lambda`` and ``eta``
    (:func:`elicit_jax.compat.thresholds.config_fields`)."""
    from elicit_jax.compat.thresholds import config_fields

    d = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)}
    thresholds = d.pop("thresholds")
    return {**d, **config_fields(thresholds)}


def config_from_dict(d: Mapping[str, Any], source: str) -> ScoreConfig:
    """Inverse of :func:`config_dict`; ``source`` says where its thresholds came from."""
    from elicit_jax.compat.thresholds import from_config_fields

    d = dict(d)
    scale = str(d.get("action_scale", "none"))
    thresholds = from_config_fields(d, source, action_scale=scale)
    names = {f.name for f in dataclasses.fields(ScoreConfig)} - {"thresholds"}
    return ScoreConfig(thresholds=thresholds, **{k: v for k, v in d.items() if k in names})
