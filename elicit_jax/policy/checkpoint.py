"""Checkpoint directories: self-describing, readable without Flax.

Layout of a training run ``runs/base`` (written atomically as a whole)::

    runs/base/artifact.json            kind "training_run": config, inputs, seeds, seed dirs
    runs/base/seed0/artifact.json      kind "checkpoint": config, model spec, dims, obs fields,
                                       data hash, seed, epochs saved, best epoch, losses
    runs/base/seed0/normalization.npz  obs_mean, obs_std  (obs_dim,)
    runs/base/seed0/params/epoch_0200.npz, ..., best.npz
    runs/base/seed0/loss.parquet       per epoch: train/val loss (mean and per member)

Each ``.npz`` holds the member-stacked parameters as named arrays, ``"Trunk_0/Dense_0/kernel"``
of shape ``(K, in, out)`` etc., so ``numpy.load`` is enough to inspect them. ``final`` is the
last epoch's file.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.artifact import read_artifact, write_json
from elicit_jax.errors import ElicitError
from elicit_jax.policy.kinds import foreign_fields

if TYPE_CHECKING:
    from elicit_jax.data.demos import Demos
    from elicit_jax.policy.base import Policy

CHECKPOINT_KIND = "checkpoint"
RUN_KIND = "training_run"
SCHEMA_VERSION = 1
SPEC_KEYS = (
    "kind",
    "obs_dim",
    "action_dim",
    "n_members",
    "hidden",
    "dropout",
    "n_components",
    "reset_every",
    "obs_fields",
    "layer_norm_eps",
    "dropout_last",
    "mdn_min_std",
)
_EPOCH_RE = re.compile(r"^epoch_(\d+)\.npz$")
NORMALIZATION = "normalization.npz"


_RUN_FILE = re.compile(
    r"^(artifact\.json|seed\d+/(artifact\.json|loss\.parquet|normalization\.npz"
    r"|params/(best|epoch_\d+)\.npz))$"
)
"""The files a training run writes (the layout above)."""


def run_owns(relative: str) -> bool:
    """Whether a training run writes the file at ``relative`` (a POSIX path in the run)."""
    return bool(_RUN_FILE.match(relative))


def epoch_file(epoch: int) -> str:
    """File name of the parameters after ``epoch`` epochs."""
    return f"epoch_{epoch:04d}.npz"


def flatten_params(params: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested param dict -> ``{"a/b/kernel": leaf}``."""
    out: dict[str, Any] = {}
    for key, value in params.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten_params(value, name + "/"))
        else:
            out[name] = value
    return out


def unflatten_params(flat: Mapping[str, np.ndarray]) -> dict[str, Any]:
    """Inverse of :func:`flatten_params`."""
    out: dict[str, Any] = {}
    for name, value in flat.items():
        node = out
        *parents, leaf = name.split("/")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    return out


def save_params(path: Path, params: Mapping[str, Any]) -> None:
    """Write member-stacked params to ``path`` (``.npz`` of named arrays)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        np.savez(f, **{k: np.asarray(v) for k, v in flatten_params(params).items()})


def load_params(path: Path) -> dict[str, Any]:
    """Read a params ``.npz`` into a nested dict of numpy arrays.

    Raises:
      ElicitError: a missing, corrupt or truncated file, or non-finite (NaN/inf) values.
    """
    from elicit_jax.data.npz import load_arrays

    if not path.is_file():
        raise ElicitError("checkpoint parameters not found", path)
    try:
        flat = load_arrays(path)
    except ElicitError as e:
        text = str(e).removeprefix(f"{path}: ")
        raise ElicitError(f"unreadable parameter file: {text}", path) from e
    for name, value in flat.items():
        if value.dtype.kind == "f" and not np.isfinite(value).all():
            bad = int((~np.isfinite(value)).sum())
            why = (
                "the training data held values too large for float32, or the file is corrupt"
                if path.name == NORMALIZATION
                else "the checkpoint is corrupt or its training diverged"
            )
            what = "statistics" if path.name == NORMALIZATION else "parameters"
            raise ElicitError(
                f"{what} hold non-finite values ({bad} NaN/inf entries in '{name}'): {why}",
                path,
            )
    return unflatten_params(flat)


def check_normalization(norm: Mapping[str, np.ndarray], path: Path) -> None:
    """Refuse observation statistics beyond :data:`~elicit_jax.data.validation.MAX_MAGNITUDE`:
    the policy was trained on absurd observations (one value of 1e30 gives its column a std of
    about 2e28, which erases the feature), so its predictions mean nothing.

    Raises:
      ElicitError: naming ``path``, the statistic and the column.
    """
    from elicit_jax.data.validation import MAX_MAGNITUDE

    for key in ("obs_mean", "obs_std"):
        values = np.abs(np.asarray(norm.get(key, ()), np.float64)).reshape(-1)
        if (values > MAX_MAGNITUDE).any():
            col = int(np.argmax(values > MAX_MAGNITUDE))
            raise ElicitError(
                f"{key}[{col}] = {values[col]:.3g}: the policy was trained on observations with "
                f"absurd values (beyond ±{MAX_MAGNITUDE:.0e}) that erase that feature; fix the "
                "data (import and train now refuse it) and train again",
                path,
            )


FILE_HASHES = "file_sha256"
"""Seed header key: relative path -> sha256 of each parameter and normalisation file, recorded
when the run is written, so parameters copied in from another run are detected."""


def file_hashes(seed_dir: Path) -> dict[str, str]:
    """Relative path -> sha256 of a seed directory's ``normalization.npz`` and
    ``params/*.npz`` (recorded in its header as :data:`FILE_HASHES`)."""
    from elicit_jax.hashing import file_sha256

    files = [seed_dir / "normalization.npz", *sorted((seed_dir / "params").glob("*.npz"))]
    return {f.relative_to(seed_dir).as_posix(): file_sha256(f) for f in files if f.is_file()}


def check_file_hash(seed_dir: Path, header: Mapping[str, Any], file: Path) -> None:
    """Refuse a parameter or normalisation file whose bytes are not the ones the seed's
    header recorded when the run was written (checkpoints written before the hashes were
    recorded are not checked).

    Raises:
      ElicitError: the file differs from, or is missing in, the recorded hashes.
    """
    from elicit_jax.hashing import file_sha256

    recorded = header.get(FILE_HASHES)
    if not isinstance(recorded, Mapping):
        return
    name = file.relative_to(seed_dir).as_posix()
    if name not in recorded:
        raise ElicitError(
            "is not one of the files this checkpoint was written with (its artifact.json "
            "records no hash for it): copied in from elsewhere?",
            file,
        )
    if file_sha256(file) != recorded[name]:
        raise ElicitError(
            "does not match the sha256 its checkpoint's artifact.json recorded when the run "
            "was written: copied from another run or changed since; retrain, or copy the "
            "whole run directory",
            file,
        )


def write_seed_header(seed_dir: Path, header: Mapping[str, Any]) -> None:
    """Write the seed directory's ``artifact.json`` (kind ``checkpoint``)."""
    write_json(seed_dir / "artifact.json", dict(header))


_WHAT = "a policy checkpoint"


def seed_dirs(path: str | Path) -> dict[int, Path]:
    """Seed -> checkpoint directory, for a run directory or a single seed directory."""
    path = Path(path)
    header = read_artifact(path, (CHECKPOINT_KIND, RUN_KIND), SCHEMA_VERSION, what=_WHAT)
    if header["kind"] == CHECKPOINT_KIND:
        return {int(header["seed"]): path}
    return {int(s): path / d for s, d in header["seed_dirs"].items()}


def list_checkpoints(path: str | Path) -> dict[int, list[int | str]]:
    """Seed -> available checkpoints (saved epochs in order, then ``"best"``)."""
    out: dict[int, list[int | str]] = {}
    for seed, d in sorted(seed_dirs(path).items()):
        epochs = sorted(
            int(m.group(1)) for f in (d / "params").glob("*.npz") if (m := _EPOCH_RE.match(f.name))
        )
        names: list[int | str] = list(epochs)
        if (d / "params" / "best.npz").exists():
            names.append("best")
        out[seed] = names
    return out


_REQUIRED = SPEC_KEYS[:8]
"""Spec keys every checkpoint records (the others have defaults for older checkpoints)."""


def checkpoint_spec(header: Mapping[str, Any], seed_dir: Path) -> Mapping[str, Any]:
    """The model spec a seed header records, checked to name a kind and its sizes.

    Raises:
      ElicitError: no spec, no model kind or a missing size, naming the seed's
        ``artifact.json`` (a checkpoint is never read as one kind by default).
    """
    spec = header.get("model")
    file = seed_dir / "artifact.json"
    if not isinstance(spec, Mapping) or not spec.get("kind"):
        raise ElicitError("checkpoint records no model kind ('model.kind' is missing)", file)
    missing = [k for k in _REQUIRED if k not in spec]
    if missing:
        raise ElicitError(f"checkpoint model spec lacks {', '.join(missing)}", file)
    return spec


def check_param_shapes(params: Mapping[str, Any], spec: Mapping[str, Any], file: Path) -> None:
    """Raise unless ``params`` have exactly the shapes the model ``spec`` builds."""
    import jax

    from elicit_jax.policy.kinds import init_members, make_module

    module = make_module(
        spec["kind"], spec["hidden"], spec["action_dim"], spec["dropout"], spec["n_components"]
    )  # LayerNorm epsilon and dropout placement do not change shapes
    expected = jax.eval_shape(
        lambda k: init_members(module, spec["kind"], k, spec["obs_dim"], spec["n_members"]),
        jax.random.key(0),
    )
    want = {k: tuple(v.shape) for k, v in flatten_params(expected).items()}
    got = {k: tuple(v.shape) for k, v in flatten_params(params).items()}
    if want != got:
        diff = sorted(set(want.items()) ^ set(got.items()))[:3]
        raise ElicitError(f"parameters do not match the model spec in artifact.json: {diff}", file)


def checkpoint_problems(path: str | Path) -> dict[int, list[str]]:
    """Seed -> problems found in its checkpoint directory (empty list: healthy).

    Reads every parameter file and the normalisation statistics, checking that each is the
    file the run was written with (:func:`check_file_hash`), opens, holds only finite numbers
    and matches the model spec; used by ``elicit-jax info``.
    """
    out: dict[int, list[str]] = {}
    for seed, d in sorted(seed_dirs(path).items()):
        problems: list[str] = []
        try:
            header = read_artifact(d, CHECKPOINT_KIND, SCHEMA_VERSION, what=_WHAT)
            spec = checkpoint_spec(header, d)
        except ElicitError as e:
            out[seed] = [f"{d}: unreadable header ({e})"]
            continue
        files = sorted((d / "params").glob("*.npz"))
        if not files:
            problems.append(f"{d / 'params'}: no parameter files")
        if not (d / "params" / "best.npz").exists():
            problems.append(f"{d / 'params'}: best.npz is missing")
        for file in [d / "normalization.npz", *files]:
            try:
                params = load_params(file)
                if file.name == NORMALIZATION:
                    check_normalization(params, file)
                else:
                    check_param_shapes(params, spec, file)
                check_file_hash(d, header, file)
            except ElicitError as e:
                problems.append(str(e))
        out[seed] = problems
    return out


def policy_spec(policy: Policy) -> dict[str, Any]:
    """The static spec of a policy, as stored in ``artifact.json``."""
    spec = {k: getattr(policy, k) for k in SPEC_KEYS}
    spec["hidden"] = list(spec["hidden"])
    spec["obs_fields"] = list(spec["obs_fields"])
    for name in foreign_fields(spec["kind"]):
        del spec[name]  # unused; older checkpoints and other models go without them
    return spec


def check_compatible(policy: Policy, demos: Demos, path: str | Path | None = None) -> None:
    """Raise :class:`ElicitError` if ``demos`` do not fit ``policy`` (dims, obs field names).

    Args:
      policy: the policy (:attr:`~elicit_jax.policy.loaded.LoadedPolicy.policy`).
      demos: the demonstrations.
      path: the demonstration file, named in the error.
    """
    if demos.obs_dim != policy.obs_dim or demos.action_dim != policy.action_dim:
        raise ElicitError(
            f"demos have obs_dim={demos.obs_dim}, action_dim={demos.action_dim} but the policy "
            f"was trained on obs_dim={policy.obs_dim}, action_dim={policy.action_dim}",
            path,
        )
    names = tuple(f.name for f in demos.obs_fields)
    if names and policy.obs_fields and names != tuple(policy.obs_fields):
        raise ElicitError(
            f"obs fields {list(names)} differ from the policy's {list(policy.obs_fields)}", path
        )
