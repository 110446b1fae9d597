"""The model registry: one :class:`ModelKind` entry per policy architecture.

Everything that differs between ``mlp``, ``mdn`` and ``lstm`` — the member's Flax module, its
training defaults and CPU-profile settings, its loss, its deterministic action, whether it has
its own predictive spread, whether it is recurrent, which stored fields only it keeps — is a
field of its entry here; the rest of the package asks the entry (``model_kind(name).recurrent``)
instead of comparing names. Adding an architecture is adding one entry to :data:`MODEL_KINDS`
(and its module to :mod:`elicit_jax.policy.models`).

This module imports neither JAX nor Flax at import time (the training config and the CLI read
the registry's defaults); the entries' functions import :mod:`elicit_jax.policy.models` when
called.

Example::

    kind = model_kind("mdn")
    module = make_module("mdn", (256, 256), action_dim=7, dropout=0.5, n_components=2)
    kind.recurrent, kind.own_spread    # (False, True)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from types import MappingProxyType
from typing import Any

from elicit_jax.errors import ElicitError


@dataclasses.dataclass(frozen=True)
class ModuleArgs:
    """What the Flax module of one member is built from (a checkpoint's or config's spec)."""

    hidden: tuple[int, ...]
    action_dim: int
    dropout: float
    n_components: int
    layer_norm_eps: float
    dropout_last: bool
    mdn_min_std: float


@dataclasses.dataclass(frozen=True)
class ModelKind:
    """One policy architecture.

    Attributes:
      name: the kind's name (``TrainConfig.model``, ``Policy.kind``, checkpoints' ``kind``).
      summary: one line for help texts.
      members: default ensemble size K.
      hidden: default hidden sizes (paper).
      lr: default Adam learning rate (paper).
      cpu: the ``cpu`` profile's training settings for this kind (see
        :mod:`elicit_jax.policy.config`).
      build: ``ModuleArgs -> nn.Module`` of one member.
      init: ``(module, key, obs_dim) -> params`` of one member.
      loss: ``(module, params, obs (B, L, O), action (B, L, A), rng, train, reduce) -> (B, L)``
        per-step training loss of one member (``reduce``: mean or sum over action dims).
      recurrent: actions depend on the history (trained on windows, scored per episode, never
        one state at a time).
      mc_dropout: MC-dropout scoring (:meth:`Policy.sample_members`) applies.
      own_spread: the model has its own predictive spread, so one member still gives a
        novelty (an ensemble of one is not degenerate).
      own_fields: config and checkpoint-spec fields stored only for this kind (other kinds
        leave them out, as they were written before the fields existed).
      predict: feed-forward only: ``(module, params, x (B, O)) -> (B, A)`` deterministic action
        of one member (None for recurrent kinds).
      spread: ``(module, params, x) -> (B, A)`` the member's own predictive std, or None.
      describe: ``spec -> str`` the kind's own details in ``info`` (", 2 components"; none by
        default).

    The flags default to a plain feed-forward kind, so an entry states only what sets it apart.
    """

    name: str
    summary: str
    members: int
    hidden: tuple[int, ...]
    lr: float
    cpu: Mapping[str, Any]
    build: Callable[[ModuleArgs], Any]
    init: Callable[[Any, Any, int], Any]
    loss: Callable[..., Any]
    recurrent: bool = False
    mc_dropout: bool = False
    own_spread: bool = False
    own_fields: tuple[str, ...] = ()
    predict: Callable[[Any, Any, Any], Any] | None = None
    spread: Callable[[Any, Any, Any], Any] | None = None
    describe: Callable[[Mapping[str, Any]], str] = lambda spec: ""


# --- the kinds' functions (JAX/Flax imported when called) ------------------------------------


def _build_mlp(a: ModuleArgs) -> Any:
    from elicit_jax.policy import models

    return models.MLPMember(a.hidden, a.action_dim, a.dropout, a.layer_norm_eps, a.dropout_last)


def _build_mdn(a: ModuleArgs) -> Any:
    from elicit_jax.policy import models

    return models.MDNMember(
        a.hidden,
        a.action_dim,
        a.dropout,
        a.n_components,
        a.layer_norm_eps,
        a.dropout_last,
        a.mdn_min_std,
    )


def _build_lstm(a: ModuleArgs) -> Any:
    from elicit_jax.policy import models

    return models.LSTMStep(a.hidden, a.action_dim)


def _init_feed_forward(module: Any, key: Any, obs_dim: int) -> Any:
    import jax.numpy as jnp

    return module.init(key, jnp.zeros((1, obs_dim), jnp.float32), False)["params"]


def _init_lstm(module: Any, key: Any, obs_dim: int) -> Any:
    import jax.numpy as jnp

    from elicit_jax.policy import models

    x = jnp.zeros((1, obs_dim), jnp.float32)
    return module.init(key, models.lstm_zero_carry(module.hidden, 1), x)["params"]


def _predict_mlp(module: Any, params: Any, x: Any) -> Any:
    return module.apply({"params": params}, x)


def _predict_mdn(module: Any, params: Any, x: Any) -> Any:
    from elicit_jax.policy import models

    logits, means, _ = module.apply({"params": params}, x)
    return models.mdn_mode(logits, means)


def _spread_mdn(module: Any, params: Any, x: Any) -> Any:
    from elicit_jax.policy import models

    return models.mdn_std(*module.apply({"params": params}, x))


def _loss_mlp(module: Any, params: Any, obs: Any, action: Any, rng: Any, train: bool, reduce: Any):
    out = module.apply({"params": params}, obs[:, 0], train, rngs={"dropout": rng})
    return reduce((out - action[:, 0]) ** 2, axis=-1)[:, None]


def _loss_mdn(module: Any, params: Any, obs: Any, action: Any, rng: Any, train: bool, reduce: Any):
    from elicit_jax.policy import models

    out = module.apply({"params": params}, obs[:, 0], train, rngs={"dropout": rng})
    return -models.mdn_log_likelihood(*out, action[:, 0])[:, None]


def _loss_lstm(module: Any, params: Any, obs: Any, action: Any, rng: Any, train: bool, reduce: Any):
    import jax.numpy as jnp

    from elicit_jax.policy import models

    reset = jnp.arange(obs.shape[1]) == 0
    pred = models.lstm_sequence(module, params, jnp.swapaxes(obs, 0, 1), reset)
    return reduce((jnp.swapaxes(pred, 0, 1) - action) ** 2, axis=-1)


_CPU_MLP = {
    "hidden": (256, 256),
    "epochs": 100,
    "checkpoint_every": 20,
    "progress_every": 5,
    "seeds": (0,),
}
_CPU_MDN = {
    "hidden": (256, 256),
    "lr": 1e-3,
    "mdn_min_std": 0.01,
    "epochs": 500,
    "checkpoint_every": 100,
    "progress_every": 10,
    "seeds": (0,),
}
_CPU_LSTM = {
    "hidden": (64, 64),
    "batch_size": 64,
    "epochs": 40,
    "checkpoint_every": 10,
    "progress_every": 1,
    "seeds": (0,),
}

MODEL_KINDS: Mapping[str, ModelKind] = MappingProxyType(
    {
        "mlp": ModelKind(
            name="mlp",
            summary="ensemble of MLPs (the paper's policy)",
            members=5,
            hidden=(1024, 1024),
            lr=1e-3,
            cpu=MappingProxyType(_CPU_MLP),
            build=_build_mlp,
            init=_init_feed_forward,
            loss=_loss_mlp,
            mc_dropout=True,
            predict=_predict_mlp,
        ),
        "mdn": ModelKind(
            name="mdn",
            summary="mixture density network (baseline)",
            members=1,
            hidden=(1024, 1024),
            lr=1e-4,
            cpu=MappingProxyType(_CPU_MDN),
            build=_build_mdn,
            init=_init_feed_forward,
            loss=_loss_mdn,
            own_spread=True,
            own_fields=("mdn_min_std",),
            predict=_predict_mdn,
            spread=_spread_mdn,
            describe=lambda spec: f", {spec['n_components']} components",
        ),
        "lstm": ModelKind(
            name="lstm",
            summary="ensemble of LSTMs (baseline)",
            members=5,
            hidden=(512, 512),
            lr=1e-3,
            cpu=MappingProxyType(_CPU_LSTM),
            build=_build_lstm,
            init=_init_lstm,
            loss=_loss_lstm,
            recurrent=True,
            describe=lambda spec: f", state reset every {spec['reset_every']} steps",
        ),
    }
)
MODELS: tuple[str, ...] = tuple(MODEL_KINDS)
OWN_FIELDS: frozenset[str] = frozenset(f for k in MODEL_KINDS.values() for f in k.own_fields)


def model_kind(name: str) -> ModelKind:
    """The registry entry of model kind ``name``.

    Raises:
      ElicitError: unknown kind (one line naming the known ones).
    """
    if name not in MODEL_KINDS:
        raise ElicitError(f"unknown model {name!r}; choose one of {', '.join(MODELS)}")
    return MODEL_KINDS[name]


def foreign_fields(name: str) -> frozenset[str]:
    """Fields other kinds keep to themselves, left out of ``name``'s stored config and spec."""
    return OWN_FIELDS - set(model_kind(name).own_fields)


def make_module(
    kind: str,
    hidden: Sequence[int],
    action_dim: int,
    dropout: float,
    n_components: int,
    *,
    layer_norm_eps: float | None = None,
    dropout_last: bool = False,
    mdn_min_std: float | None = None,
) -> Any:
    """The Flax module of one member of a ``kind`` model (``mdn_min_std``: the MDN's floor on
    component stds; ``None`` for the defaults of :mod:`elicit_jax.policy.models`)."""
    from elicit_jax.policy import models

    args = ModuleArgs(
        hidden=tuple(int(h) for h in hidden),
        action_dim=int(action_dim),
        dropout=dropout,
        n_components=n_components,
        layer_norm_eps=float(models.LAYER_NORM_EPS if layer_norm_eps is None else layer_norm_eps),
        dropout_last=bool(dropout_last),
        mdn_min_std=float(models.MDN_MIN_STD if mdn_min_std is None else mdn_min_std),
    )
    return model_kind(kind).build(args)


def init_members(module: Any, kind: str, key: Any, obs_dim: int, n_members: int) -> Any:
    """Stacked parameters of ``n_members`` independently initialised members (leading axis K).

    Recurrent members are initialised one by one and stacked: a batched QR (the LSTM's
    orthogonal recurrent initialiser under ``vmap``) deadlocks XLA:CPU in jax 0.10 for
    hidden >= 64.
    """
    import jax
    import jax.numpy as jnp

    entry = model_kind(kind)
    keys = jax.random.split(key, n_members)
    if entry.recurrent:
        members = [entry.init(module, keys[i], obs_dim) for i in range(n_members)]
        return jax.tree.map(lambda *xs: jnp.stack(xs), *members)
    return jax.vmap(lambda k: entry.init(module, k, obs_dim))(keys)
