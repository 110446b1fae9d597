"""Training configuration: a frozen dataclass with the paper's defaults, and named profiles.

Defaults follow the paper (``docs/method.md``): an MLP ensemble of 5 members, 2 x 1024 hidden
units, dropout 0.5, Adam lr 1e-3 (MDN: 1e-4), batch 512, 1000 epochs, checkpoints every 200
epochs, 3 seeds.
Fields left ``None`` take their model-specific default when the config is built
(:meth:`TrainConfig.__post_init__`), so a stored config is always explicit.

Profiles (:data:`PROFILES`):
  * ``paper``: exactly the defaults above (LSTM: 5 x 2 x 512, windows of 10 steps).
  * ``cpu``: small enough to train in about a minute on 2 CPU cores on ~50 demos x 100 steps:
    hidden 2 x 256, 100 epochs, checkpoints every 20 epochs, 1 seed. The baselines get the
    settings that reach the MLP's held-out action error in that time (chosen on validation
    episodes of square-nut's base demos, never on rollouts):

    - MDN: 500 epochs (one network trains them in the time the 5-member MLP ensemble trains
      100), Adam lr 1e-3 (the paper's 1e-4 is for 1000 epochs: after 100 its likelihood was
      still falling and its action error was 5x the MLP's) and a floor of 0.01 on every
      component's std (as robomimic's GMM policy), not 1e-4: in constant action dims and at
      actions saturated at +-1 the std otherwise collapses towards the floor, and those dims'
      likelihood terms (-log std) dominate the loss and its gradients.
    - LSTM: 2 x 64, 40 epochs of minibatches of 64 windows (640 steps, near the MLP's 512
      samples): a window of ``seq_len`` steps starts at every step, so an epoch already runs
      ``seq_len`` times the MLP's sample-steps, and 512 windows gave only ~9 updates an epoch.
  * ``original-code``: the paper's sizes trained as the original (PyTorch) code does, where it
    differs from the paper's text: dropout after *both* hidden layers (before the head too),
    squared error *summed* over action dims, gradients clipped at global norm 10, LayerNorm
    epsilon 1e-5.

:data:`PROFILES` is the one table of profiles (a pipeline accepts those marked
``pipelines``: :data:`PIPELINE_PROFILES`); each kind's ``cpu`` settings are its entry's
(:attr:`elicit_jax.policy.kinds.ModelKind.cpu`), its defaults its entry's too.

:func:`default_profile` picks ``paper`` on an accelerator and ``cpu`` on a CPU-only machine
(the ``train`` command prints its choice).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.policy.kinds import MODELS, foreign_fields, model_kind

__all__ = ["MODELS", "PIPELINE_PROFILES", "PROFILES", "Profile", "TrainConfig", "default_profile"]
LOSSES = ("mean", "sum")
MAX_LR = 1.0
"""Largest Adam learning rate accepted (every command and pipeline: :class:`TrainConfig`)."""
MAX_BATCH_SIZE = 1 << 16
"""Largest minibatch accepted, in samples (65,536: 128 times the paper's 512); beyond it one
batch's activations outgrow a machine's memory."""


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """How to train a base policy.

    Attributes:
      model: ``mlp`` (ensemble, default), ``mdn`` or ``lstm``.
      ensemble_size: members K (None: 5, MDN 1).
      hidden: hidden sizes (None: 2 x 1024, LSTM 2 x 512).
      dropout: dropout between hidden layers of the MLP/MDN trunk (LSTM: unused).
      lr: Adam learning rate (None: 1e-3, MDN 1e-4).
      batch_size: minibatch size (samples; LSTM: windows).
      epochs: passes over the training split.
      checkpoint_every: save parameters every this many epochs (plus final and best).
      progress_every: epochs per jitted chunk between progress updates (a divisor of
        ``gcd(epochs, checkpoint_every)`` is used, so every chunk has the same length).
      val_fraction: fraction of EPISODES held out for validation (at least one when there are
        two or more episodes and the fraction is positive).
      bootstrap: resample each member's training set with replacement (ThriftyDAgger-style).
      grad_clip: clip gradients by global norm (None: off; the original code used 10).
      loss: squared error over action dims: ``mean`` (paper) or ``sum`` (original code).
      layer_norm_eps: LayerNorm epsilon (Flax's 1e-6; PyTorch's 1e-5 in the original code).
      dropout_last: dropout after the last hidden layer too (original code), not only
        between hidden layers (paper).
      seq_len: LSTM training window length; acting resets the state every ``seq_len`` steps.
      n_components: MDN mixture components.
      mdn_min_std: MDN floor on every component's std (actions live in [-1, 1]).
      seeds: training seeds; each gives one checkpoint directory ``seed<k>``.
      vmap_seeds: train all seeds in one vmapped call (else one after another).

    Training is bit-for-bit reproducible for the same config on the same machine and library
    versions; a seed trained alone and the same seed trained in a vmapped group can differ in
    the last bits (different XLA programs).
    """

    model: str = "mlp"
    ensemble_size: int | None = None
    hidden: tuple[int, ...] | None = None
    dropout: float = 0.5
    lr: float | None = None
    batch_size: int = 512
    epochs: int = 1000
    checkpoint_every: int = 200
    progress_every: int = 10
    val_fraction: float = 0.1
    bootstrap: bool = False
    grad_clip: float | None = None
    loss: str = "mean"
    layer_norm_eps: float = 1e-6
    dropout_last: bool = False
    seq_len: int = 10
    n_components: int = 2
    mdn_min_std: float = 1e-4
    seeds: tuple[int, ...] = (0, 1, 2)
    vmap_seeds: bool = True

    def __post_init__(self) -> None:
        kind = model_kind(self.model)
        fill = {"ensemble_size": kind.members, "hidden": kind.hidden, "lr": kind.lr}
        for name, value in fill.items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, value)
        object.__setattr__(self, "hidden", tuple(int(h) for h in self.hidden))
        object.__setattr__(self, "seeds", tuple(int(s) for s in self.seeds))
        self._check()

    def _check(self) -> None:
        checks = (
            (self.ensemble_size >= 1, "ensemble_size must be >= 1"),
            (len(self.hidden) >= 1 and min(self.hidden) >= 1, "hidden sizes must be >= 1"),
            (0.0 <= self.dropout < 1.0, "dropout must be in [0, 1)"),
            (
                math.isfinite(self.lr) and 0 < self.lr <= MAX_LR,
                f"lr must be a number in (0, {MAX_LR:g}], got {self.lr:g} (Adam diverges "
                "beyond; the paper uses 1e-3)",
            ),
            (
                1 <= self.batch_size <= MAX_BATCH_SIZE,
                f"batch_size must be in 1..{MAX_BATCH_SIZE}, got {self.batch_size} (a larger "
                "minibatch does not fit in memory; the paper uses 512)",
            ),
            (self.epochs >= 1, "epochs must be >= 1"),
            (self.checkpoint_every >= 1, "checkpoint_every must be >= 1"),
            (self.progress_every >= 1, "progress_every must be >= 1"),
            (0.0 <= self.val_fraction < 1.0, "val_fraction must be in [0, 1)"),
            (self.grad_clip is None or self.grad_clip > 0, "grad_clip must be > 0"),
            (self.loss in LOSSES, f"loss must be one of {', '.join(LOSSES)}"),
            (self.layer_norm_eps > 0, "layer_norm_eps must be > 0"),
            (self.seq_len >= 1, "seq_len must be >= 1"),
            (self.n_components >= 1, "n_components must be >= 1"),
            (0.0 < self.mdn_min_std < 1.0, "mdn_min_std must be in (0, 1)"),
            (len(self.seeds) >= 1, "at least one seed is needed"),
            (len(set(self.seeds)) == len(self.seeds), "seeds must be distinct"),
        )
        for ok, msg in checks:
            if not ok:
                raise ElicitError(f"invalid training config: {msg}")

    @classmethod
    def from_profile(cls, profile: str = "paper", **overrides: Any) -> TrainConfig:
        """A config from a named profile (:data:`PROFILES`) with field overrides.

        ``None`` overrides are ignored, so CLI flags can be passed straight through.
        """
        if profile not in PROFILES:
            raise ElicitError(f"unknown profile {profile!r}; choose one of {', '.join(PROFILES)}")
        overrides = {k: v for k, v in overrides.items() if v is not None}
        unknown = set(overrides) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ElicitError(f"unknown training option(s): {', '.join(sorted(unknown))}")
        model = overrides.get("model", "mlp")
        return cls(**{**PROFILES[profile].settings(model), **overrides})

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (tuples become lists). A kind's own fields (``mdn_min_std``: the
        MDN's, :attr:`~elicit_jax.policy.kinds.ModelKind.own_fields`) only for that kind: other
        models ignore them, and leaving them out keeps their stored configs (and the
        pipeline's stage identities) as they were before the settings existed."""
        out = dataclasses.asdict(self)
        for name in foreign_fields(self.model):
            del out[name]
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrainConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - names
        if unknown:
            raise ElicitError(f"unknown training config key(s): {', '.join(sorted(unknown))}")
        data = dict(data)
        for key in ("hidden", "seeds"):
            if data.get(key) is not None:
                data[key] = tuple(data[key])
        return cls(**data)


@dataclasses.dataclass(frozen=True)
class Profile:
    """A named set of training settings.

    Attributes:
      name: the profile's name (``--profile``, a pipeline's ``profile``).
      settings: ``model -> field values`` of :class:`TrainConfig` under this profile.
      pipelines: pipelines may run under it (their reports describe ``paper`` and ``cpu``).
    """

    name: str
    settings: Callable[[str], dict[str, Any]]
    pipelines: bool


def _paper(model: str) -> dict[str, Any]:
    return {"model": model}


def _cpu(model: str) -> dict[str, Any]:
    return {"model": model, **model_kind(model).cpu}


def _original_code(model: str) -> dict[str, Any]:
    return {
        "model": model,
        "dropout_last": True,
        "loss": "sum",
        "grad_clip": 10.0,
        "layer_norm_eps": 1e-5,
    }


PROFILES: Mapping[str, Profile] = MappingProxyType(
    {
        p.name: p
        for p in (
            Profile("paper", _paper, pipelines=True),
            Profile("cpu", _cpu, pipelines=True),
            Profile("original-code", _original_code, pipelines=False),
        )
    }
)
PIPELINE_PROFILES: tuple[str, ...] = tuple(p.name for p in PROFILES.values() if p.pipelines)


def default_profile() -> tuple[str, str]:
    """The profile to use when none is given, and why: ``paper`` when JAX has an accelerator,
    ``cpu`` when it runs on the CPU (the paper's sizes take about 20 minutes per model on a
    2-core CPU)."""
    import jax

    backend = jax.default_backend()
    if backend == "cpu":
        return "cpu", "JAX runs on the CPU"
    return "paper", f"JAX runs on {backend}"
