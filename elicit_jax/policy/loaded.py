"""The one policy loader: a checkpoint read once into a typed :class:`LoadedPolicy`.

Every command and stage that runs a trained policy (``score``, ``evaluate``, elicitation
sessions and ``watch``, ``serve``, the pipeline stages) loads it with :func:`load_policy`, which
checks the checkpoint's header (kind, schema version, a known model kind), its parameter and
normalisation files (present, finite, the shapes the spec builds, the bytes the run recorded)
and, when given the task it is to run on, its observation and action sizes against the task's
(the task registry's sizes, :mod:`elicit_jax.sim.registry`).

Example::

    loaded = load_policy("runs/base", "best", task=task_entry("square-nut"))
    loaded.policy.members(obs)       # the Policy pytree the jitted code takes
    loaded.kind.recurrent, loaded.task, loaded.sha256
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from elicit_jax.artifact import read_artifact
from elicit_jax.errors import ElicitError
from elicit_jax.policy import checkpoint as ckpt
from elicit_jax.policy.kinds import ModelKind, model_kind

if TYPE_CHECKING:
    from elicit_jax.policy.base import Policy
    from elicit_jax.policy.config import TrainConfig

UNKNOWN_TASKS = ("", "unknown")
"""Recorded task names that name no task."""


class TaskSizes(Protocol):
    """What a task tells the loader: its name and the sizes its policies must have
    (:class:`~elicit_jax.sim.registry.TaskEntry` is one)."""

    @property
    def name(self) -> str: ...

    @property
    def obs_dim(self) -> int: ...

    @property
    def action_dim(self) -> int: ...


@dataclasses.dataclass(frozen=True, eq=False)
class LoadedPolicy:
    """A checkpoint read once: the policy and what its run records about it.

    Attributes:
      policy: the :class:`~elicit_jax.policy.base.Policy` pytree (params, normalisation,
        static spec) that the jitted scorers and rollouts take.
      kind: the registry entry of its model kind (:mod:`elicit_jax.policy.kinds`).
      task: the task its training data recorded (None: none, or ``unknown``).
      seed: the training seed of the checkpoint.
      config: the training config as stored in its header (``{}`` when it records none).
      seed_dir: the seed directory it was read from.
      source: the path as given (named in errors, recorded as an input).
    """

    policy: Policy
    kind: ModelKind
    task: str | None
    seed: int
    config: Mapping[str, Any]
    seed_dir: Path
    source: str

    @property
    def obs_dim(self) -> int:
        """Observation size O."""
        return int(self.policy.obs_dim)

    @property
    def action_dim(self) -> int:
        """Action size A."""
        return int(self.policy.action_dim)

    @property
    def obs_fields(self) -> tuple[str, ...]:
        """Names of the observation fields, in order (empty when the run records none)."""
        return tuple(self.policy.obs_fields)

    @property
    def normalization(self) -> dict[str, Any]:
        """The training statistics: ``obs_mean``, ``obs_std`` and ``action_std`` (None for
        checkpoints that predate it)."""
        p = self.policy
        return {"obs_mean": p.obs_mean, "obs_std": p.obs_std, "action_std": p.action_std}

    @functools.cached_property
    def sha256(self) -> str:
        """:func:`policy_sha256` of the policy (what thresholds record as ``policy_sha256``)."""
        return policy_sha256(self.policy)

    def train_config(self) -> TrainConfig:
        """The :class:`~elicit_jax.policy.config.TrainConfig` the policy was trained with,
        restricted to its own training seed (how π_new is retrained between batches).

        Raises:
          ElicitError: the header records no training config, or an invalid one.
        """
        from elicit_jax.policy.config import TrainConfig

        if not self.config:
            raise ElicitError(
                "checkpoint header records no training config to retrain with", self.source
            )
        config = TrainConfig.from_dict(self.config)
        return dataclasses.replace(config, seeds=(self.seed,))

    def check_task(self, task: TaskSizes) -> None:
        """Refuse a policy whose sizes are not the ones ``task`` gives and takes.

        Raises:
          ElicitError: one line naming the checkpoint, its sizes and the task's.
        """
        if (self.obs_dim, self.action_dim) != (int(task.obs_dim), int(task.action_dim)):
            raise ElicitError(
                f"policy has obs_dim={self.obs_dim}, action_dim={self.action_dim}; task "
                f"'{task.name}' needs obs_dim={task.obs_dim}, action_dim={task.action_dim}",
                self.source,
            )


def load_policy(
    path: str | Path,
    which: str | int = "best",
    *,
    seed: int | None = None,
    task: TaskSizes | None = None,
) -> LoadedPolicy:
    """Read a checkpoint once into a :class:`LoadedPolicy` (the one policy loader).

    Args:
      path: a seed directory (``runs/base/seed0``) or a run directory with one seed (or pass
        ``seed``).
      which: ``"best"`` (lowest validation loss), ``"final"`` (last epoch) or an epoch number
        (an int or its digits).
      seed: pick this seed of a run directory.
      task: the task the policy is to run on; its sizes are checked against the checkpoint's.

    Raises:
      ElicitError: missing directory, checkpoint or seed; a header of another kind or a newer
        schema; no or an unknown model kind; parameters not matching the spec; sizes not the
        task's.
    """
    import jax
    import jax.numpy as jnp

    from elicit_jax.policy.base import Policy

    if isinstance(which, str) and which.isdigit():
        which = int(which)
    seed_dir = _resolve_seed_dir(Path(path), seed)
    header = read_artifact(seed_dir, ckpt.CHECKPOINT_KIND, ckpt.SCHEMA_VERSION)
    spec, kind = _spec_of(header, seed_dir)
    file = _params_file(seed_dir, header, which)
    params = ckpt.load_params(file)
    norm = ckpt.load_params(seed_dir / ckpt.NORMALIZATION)
    ckpt.check_normalization(norm, seed_dir / ckpt.NORMALIZATION)
    ckpt.check_param_shapes(params, spec, file)
    for f in (file, seed_dir / ckpt.NORMALIZATION):
        ckpt.check_file_hash(seed_dir, header, f)
    optional = {k: spec[k] for k in ("layer_norm_eps", "dropout_last", "mdn_min_std") if k in spec}
    policy = Policy(
        params=jax.tree.map(jnp.asarray, params),
        obs_mean=jnp.asarray(norm["obs_mean"]),
        obs_std=jnp.asarray(norm["obs_std"]),
        kind=kind.name,
        obs_dim=int(spec["obs_dim"]),
        action_dim=int(spec["action_dim"]),
        n_members=int(spec["n_members"]),
        hidden=tuple(int(h) for h in spec["hidden"]),
        dropout=float(spec["dropout"]),
        n_components=int(spec["n_components"]),
        reset_every=int(spec["reset_every"]),
        obs_fields=tuple(spec.get("obs_fields", ())),
        action_std=jnp.asarray(norm["action_std"]) if "action_std" in norm else None,
        **_typed(optional),
    )
    loaded = LoadedPolicy(
        policy=policy,
        kind=kind,
        task=recorded_task(seed_dir, header),
        seed=int(header["seed"]),
        config=dict(header.get("config") or {}),
        seed_dir=seed_dir,
        source=str(path),
    )
    if task is not None:
        loaded.check_task(task)
    return loaded


def policy_sha256(policy: Policy) -> str:
    """Content hash of what a policy computes with: its kind, every parameter array (name,
    dtype, shape, values) and its normalisation. The same checkpoint gives the same hash
    however its path was given; thresholds record it to name the policy they were fitted for.
    """
    import hashlib

    import jax

    h = hashlib.sha256(str(policy.kind).encode())
    parts = {
        "params": policy.params,
        "obs_mean": policy.obs_mean,
        "obs_std": policy.obs_std,
        "action_std": policy.action_std,
    }
    for path, leaf in sorted(
        jax.tree_util.tree_flatten_with_path(parts)[0], key=lambda kv: jax.tree_util.keystr(kv[0])
    ):
        arr = np.ascontiguousarray(np.asarray(leaf))
        h.update(f"{jax.tree_util.keystr(path)}|{arr.dtype.str}|{arr.shape}".encode())
        h.update(arr.tobytes())
    return h.hexdigest()


def _resolve_seed_dir(path: Path, seed: int | None) -> Path:
    dirs = ckpt.seed_dirs(path)
    if seed is not None:
        if seed not in dirs:
            raise ElicitError(f"no seed {seed}; available seeds: {sorted(dirs)}", path)
        return dirs[seed]
    if len(dirs) > 1:
        first = sorted(dirs)[0]
        raise ElicitError(
            f"holds seeds {sorted(dirs)}; pass a seed directory (e.g. {dirs[first]}) or seed=",
            path,
        )
    return next(iter(dirs.values()))


def _spec_of(header: Mapping[str, Any], seed_dir: Path) -> tuple[Mapping[str, Any], ModelKind]:
    """The model spec of a seed header and its kind's registry entry."""
    spec = ckpt.checkpoint_spec(header, seed_dir)
    try:
        return spec, model_kind(str(spec["kind"]))
    except ElicitError as e:
        raise ElicitError(f"{e} (checkpoint model spec)", seed_dir / "artifact.json") from None


def recorded_task(path: str | Path, header: Mapping[str, Any] | None = None) -> str | None:
    """The task a policy's training data recorded, from headers alone (no parameters read):
    what :attr:`LoadedPolicy.task` holds, and what ``--task`` defaults to
    (:mod:`elicit_jax.sim.task_match`).

    Args:
      path: a run directory, one of its seed directories (of an older run, which records no
        task itself: its run's), or a demos artifact.
      header: ``path``'s header when already read (read here otherwise).

    Returns:
      The recorded task, or None for none / ``unknown``.
    """
    from elicit_jax.artifact import read_header

    path = Path(path)
    task = (read_header(path) if header is None else header).get("task")
    if task is None and path.is_dir() and (path.parent / "artifact.json").is_file():
        task = read_header(path.parent).get("task")
    return None if task is None or str(task).strip().lower() in UNKNOWN_TASKS else str(task)


def _typed(optional: Mapping[str, Any]) -> dict[str, Any]:
    """Spec fields older checkpoints may lack (the Policy's defaults apply), typed."""
    types = {"layer_norm_eps": float, "dropout_last": bool, "mdn_min_std": float}
    return {k: types[k](v) for k, v in optional.items()}


def _params_file(seed_dir: Path, header: Mapping[str, Any], which: str | int) -> Path:
    """The parameter file of checkpoint ``which`` (best, final or an epoch number)."""
    if which == "final":
        which = int(header["final_epoch"])
    if which == "best":
        return seed_dir / "params" / "best.npz"
    if isinstance(which, int):
        file = seed_dir / "params" / ckpt.epoch_file(which)
        if not file.exists():
            avail = ckpt.list_checkpoints(seed_dir)[int(header["seed"])]
            raise ElicitError(f"no checkpoint for epoch {which}; available: {avail}", seed_dir)
        return file
    raise ElicitError(f"unknown checkpoint {which!r}; use best, final or an epoch number")
