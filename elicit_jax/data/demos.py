"""The demonstration artifact: one Parquet row per step, episodes contiguous.

Columns: ``episode`` (int64), ``operator`` (string), ``step`` (int32, 0..T-1 per episode),
``obs`` (fixed-size list<float32>[obs_dim]), ``action`` (fixed-size list<float32>[act_dim]),
``reward`` (float32), ``success`` (bool, the episode's outcome), plus optional extra columns.
The header (schema metadata, see :mod:`elicit_jax.artifact`) holds the schema version,
dimensions, observation field slices, task name, action bounds and provenance.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import make_header, read_artifact, write_parquet
from elicit_jax.data.columns import (
    column_to_numpy,
    demos_to_table,
    fixed_to_numpy,
    numeric_column,
    parse_bound,
    read_table,
)
from elicit_jax.data.demo_set import (
    ARRAY_FIELDS,
    SOURCE_EPISODE,
    TASK_COLUMN,
    Demos,
    ObsField,
    fields_from_sizes,
)
from elicit_jax.data.validation import (
    BoundsPolicy,
    DemosWarning,
    check_episode_layout,
    validate,
)
from elicit_jax.errors import ElicitError

DEMOS_KIND = "demos"
DEMOS_SCHEMA_VERSION = 1
CORE_COLUMNS = ("episode", "operator", "step", "obs", "action", "reward", "success")


def episode_digest(obs: np.ndarray, action: np.ndarray, reward: np.ndarray | None = None) -> str:
    """Content hash of one imported episode: its float32 ``obs (T, O)``, ``action (T, A)`` and
    ``reward (T,)`` (if any), shapes included.

    Importers record it per source episode (``provenance['episode_sha256']``) so an export can
    check that the demos it names are still the same in the source dataset, whatever else
    changed in that file (e.g. masks added by robomimic's own scripts).
    """
    import hashlib

    h = hashlib.sha256()
    for arr in (obs, action) if reward is None else (obs, action, reward):
        arr = np.ascontiguousarray(arr, dtype=np.float32)
        h.update(repr(arr.shape).encode())
        h.update(arr.tobytes())
    return h.hexdigest()


def make_provenance(source: str | Path, importer: str, **fields: Any) -> dict[str, Any]:
    """Provenance of imported data: source path, its sha256, importer, time, and ``fields``."""
    from elicit_jax.artifact import file_sha256, now_utc

    return {
        "source": str(Path(source).resolve()),
        "sha256": file_sha256(source),
        "importer": importer,
        "imported": now_utc(),
        **fields,
    }


def concat_demos(parts: Sequence[Demos], renumber: bool = True) -> Demos:
    """Concatenate demo sets of equal dims; episode ids renumbered 0..E-1 when ``renumber``.

    Sets of different tasks (or with a per-step ``task`` column) keep each step's task in
    the ``task`` column; the result's task then names them all, joined by `` | ``.
    """
    if not parts:
        raise ElicitError("nothing to concatenate: no demonstration sets given")
    parts = _with_task_column(parts)
    first = parts[0]
    for p in parts[1:]:
        if (p.obs_dim, p.action_dim) != (first.obs_dim, first.action_dim):
            raise ElicitError(
                f"cannot combine demos of dims obs={p.obs_dim}, act={p.action_dim} with "
                f"obs={first.obs_dim}, act={first.action_dim}"
            )
    arrays = {k: np.concatenate([getattr(p, k) for p in parts]) for k in ARRAY_FIELDS}
    common = set.intersection(*(set(p.extra) for p in parts))
    extra = {k: np.concatenate([p.extra[k] for p in parts]) for k in sorted(common)}
    if renumber:
        offsets, ep = 0, []
        for p in parts:
            _, inverse = np.unique(p.episode, return_inverse=True)
            order = _first_seen_rank(p.episode)
            ep.append(order + offsets)
            offsets += int(inverse.max()) + 1 if p.n_steps else 0
        arrays["episode"] = np.concatenate(ep).astype(np.int64)
    provenance = dict(first.provenance)
    if any(dict(p.provenance) != provenance for p in parts[1:]):
        provenance = {"parts": [dict(p.provenance) for p in parts]}
    task = first.task
    if TASK_COLUMN in extra:
        task = " | ".join(dict.fromkeys(str(t) for t in extra[TASK_COLUMN]))
    return dataclasses.replace(first, **arrays, extra=extra, provenance=provenance, task=task)


def _with_task_column(parts: Sequence[Demos]) -> Sequence[Demos]:
    """The parts, each with a per-step ``task`` column if they differ in task."""
    if len({p.task for p in parts}) == 1 and not any(TASK_COLUMN in p.extra for p in parts):
        return parts
    return [
        p
        if TASK_COLUMN in p.extra
        else dataclasses.replace(
            p, extra={**p.extra, TASK_COLUMN: np.full(p.n_steps, p.task, dtype=object)}
        )
        for p in parts
    ]


def _first_seen_rank(ids: np.ndarray) -> np.ndarray:
    """Map ids to 0..E-1 by first appearance."""
    _, first_idx, inverse = np.unique(ids, return_index=True, return_inverse=True)
    rank = np.argsort(np.argsort(first_idx))
    return rank[inverse].astype(np.int64)


def from_episodes(
    episodes: Sequence[Mapping[str, np.ndarray]],
    *,
    operators: Sequence[str] | str = "unknown",
    successes: Sequence[bool] | None = None,
    episode_ids: Sequence[int] | None = None,
    **meta: Any,
) -> Demos:
    """Build :class:`Demos` from per-episode ``{"obs": (T, O), "action": (T, A), ...}``.

    Optional per-episode keys: ``reward`` (T,). Other keys of matching length become
    extra columns. ``meta`` fills the remaining :class:`Demos` fields.
    """
    n = len(episodes)
    if n == 0:
        raise ElicitError("no episodes to build a demonstration set from")
    if isinstance(operators, str):
        operators = [operators] * n
    successes = [True] * n if successes is None else list(successes)
    ids = list(range(n)) if episode_ids is None else list(episode_ids)
    for name, seq in (("operators", operators), ("successes", successes), ("episode_ids", ids)):
        if len(seq) != n:
            raise ElicitError(f"{name} has {len(seq)} entries for {n} episodes")
    cols: dict[str, list[np.ndarray]] = {k: [] for k in ARRAY_FIELDS}
    extra_keys = sorted(
        set.intersection(*(set(ep) for ep in episodes)) - {"obs", "action", "reward"}
    )
    extra: dict[str, list[np.ndarray]] = {k: [] for k in extra_keys}
    for i, ep in enumerate(episodes):
        t = len(ep["obs"])
        if t == 0:
            raise ElicitError(f"episode {ids[i]} is empty (0 steps)")
        for key in ("action", "reward", *extra_keys):
            if key in ep and len(ep[key]) != t:
                raise ElicitError(
                    f"episode {ids[i]}: '{key}' has {len(ep[key])} steps but 'obs' has {t}"
                )
        cols["obs"].append(np.asarray(ep["obs"], np.float32).reshape(t, -1))
        cols["action"].append(np.asarray(ep["action"], np.float32).reshape(t, -1))
        cols["reward"].append(np.asarray(ep.get("reward", np.zeros(t)), np.float32).reshape(t))
        cols["episode"].append(np.full(t, ids[i], np.int64))
        cols["operator"].append(np.full(t, str(operators[i]), dtype=object))
        cols["step"].append(np.arange(t, dtype=np.int32))
        cols["success"].append(np.full(t, bool(successes[i])))
        for k in extra_keys:
            extra[k].append(np.asarray(ep[k]))
    for key in ("obs", "action"):
        widths = {c.shape[1] for c in cols[key]}
        if len(widths) > 1:
            i = next(j for j, c in enumerate(cols[key]) if c.shape[1] != cols[key][0].shape[1])
            raise ElicitError(
                f"episode {ids[i]}: '{key}' has width {cols[key][i].shape[1]}, "
                f"episode {ids[0]} has {cols[key][0].shape[1]}"
            )
    arrays = {k: np.concatenate(v) for k, v in cols.items()}
    return Demos(**arrays, extra={k: np.concatenate(v) for k, v in extra.items()}, **meta)


def write_demos(
    path: str | Path,
    demos: Demos,
    *,
    config: Mapping[str, Any] | None = None,
    inputs: Mapping[str, str | Path] | None = None,
    seed: int | None = None,
    bounds: BoundsPolicy = "error",
) -> Demos:
    """Validate and atomically write ``demos`` to a Parquet artifact; returns what was written.

    Args:
      path: destination ``.parquet`` file (replaced atomically).
      demos: the demonstrations.
      config: the config that produced them (stored in the header).
      inputs: name -> path of the files they came from (hashed into the header).
      seed: PRNG seed, if any.
      bounds: out-of-bounds actions: ``error``, ``warn`` (kept, and later reads warn
        too) or ``clip`` (written clipped). Recorded in the header.
    """
    demos = validate(demos, str(path), bounds=bounds)
    header = make_header(
        DEMOS_KIND,
        DEMOS_SCHEMA_VERSION,
        config=config,
        inputs=inputs,
        seed=seed,
        task=demos.task,
        obs_dim=demos.obs_dim,
        action_dim=demos.action_dim,
        obs_fields={f.name: [f.start, f.stop] for f in demos.obs_fields},
        action_low=demos.action_low,
        action_high=demos.action_high,
        action_bounds_policy=bounds,
        provenance=dict(demos.provenance),
        n_episodes=demos.n_episodes,
        n_steps=demos.n_steps,
        extra_columns=sorted(demos.extra),
    )
    try:
        write_parquet(path, demos_to_table(demos), header)
    except OSError as e:  # e.g. a full disk: pyarrow's error names no file
        raise ElicitError(
            f"cannot write ({e}); nothing was written (a full disk or a file size limit?)", path
        ) from e
    return demos


def read_demos_header(path: str | Path) -> dict[str, Any]:
    """The header of a demonstrations artifact, checked: its kind and a schema version this
    elicit-jax understands (every reader, streaming or not, starts here).

    Raises:
      ElicitError: another kind of artifact, or a bad or newer schema version.
    """
    return read_artifact(path, DEMOS_KIND, DEMOS_SCHEMA_VERSION, what="demonstrations")


def check_episode_count(header: Mapping[str, Any], episode: np.ndarray, path: str | Path) -> None:
    """The header's ``n_episodes`` matches the distinct ids of the ``episode`` column."""
    n_unique = len(np.unique(episode))
    if "n_episodes" in header and int(header["n_episodes"]) != n_unique:
        raise ElicitError(
            f"header lists {header['n_episodes']} episodes but the file holds {n_unique} "
            "(an empty or truncated episode?)",
            path,
        )


def check_demos_layout(path: str | Path) -> dict[str, Any]:
    """Check a demonstrations artifact the way :func:`read_demos` does, without loading its
    obs and actions (a streaming reader checks those per batch): the header
    (:func:`read_demos_header`), the core columns, and the episode layout
    (:func:`~elicit_jax.data.validation.check_episode_layout`). Returns the header.

    Raises:
      ElicitError: one line naming the file and the first problem found.
    """
    import pyarrow.parquet as pq

    header = read_demos_header(path)
    try:
        names = pq.read_schema(path).names
    except Exception as e:  # pyarrow raises several types for corrupt input
        raise ElicitError(f"not a readable Parquet file ({type(e).__name__}: {e})", path) from e
    missing = [c for c in CORE_COLUMNS if c not in names]
    if missing:
        raise ElicitError(f"missing column(s) {', '.join(missing)}", path)
    table = read_table(path, ["episode", "operator", "step", "success"])
    for name in table.column_names:
        if table.column(name).null_count:
            raise ElicitError(
                f"column '{name}' has {table.column(name).null_count} null rows", path
            )
    episode = numeric_column(table, "episode", np.int64, path)
    constant = {
        "operator": np.asarray([str(x) for x in table.column("operator").to_pylist()], object),
        "success": numeric_column(table, "success", bool, path),
    }
    step = numeric_column(table, "step", np.int32, path)
    check_episode_layout(episode, step, constant, str(path))
    check_episode_count(header, episode, path)
    return header


def read_demos(path: str | Path, *, bounds: BoundsPolicy | None = None) -> Demos:
    """Read and validate a demonstration artifact.

    Args:
      path: the Parquet file.
      bounds: what to do with actions outside their declared bounds: ``error``, ``warn``
        or ``clip``; ``None`` (default) uses the policy recorded when the file was written
        (``error`` unless the importer was told otherwise).

    Raises:
      ElicitError: one line naming the file (and episode/step) of the first problem found.
    """
    header = read_demos_header(path)
    table = read_table(path)
    missing = [
        c for c in (*CORE_COLUMNS, *header.get("extra_columns", [])) if c not in table.column_names
    ]
    if missing:
        raise ElicitError(f"missing column(s) {', '.join(missing)}", path)
    for name in ("episode", "operator", "step", "reward", "success"):
        if table.column(name).null_count:
            raise ElicitError(
                f"column '{name}' has {table.column(name).null_count} null rows", path
            )
    obs = fixed_to_numpy(table, "obs", path)
    action = fixed_to_numpy(table, "action", path)
    for name, arr, key in (("obs", obs, "obs_dim"), ("action", action, "action_dim")):
        if key in header and arr.shape[1] != int(header[key]):
            raise ElicitError(
                f"column '{name}' has width {arr.shape[1]} but header says {key}={header[key]}",
                path,
            )
    extra = {k: column_to_numpy(table, k, path) for k in header.get("extra_columns", [])}
    try:
        demos = Demos(
            obs=obs,
            action=action,
            episode=numeric_column(table, "episode", np.int64, path),
            operator=np.asarray([str(x) for x in table.column("operator").to_pylist()], object),
            step=numeric_column(table, "step", np.int32, path),
            reward=numeric_column(table, "reward", np.float32, path),
            success=numeric_column(table, "success", bool, path),
            task=str(header.get("task", "unknown")),
            obs_fields=tuple(
                ObsField(str(n), int(a), int(b))
                for n, (a, b) in sorted(
                    header.get("obs_fields", {}).items(), key=lambda kv: int(kv[1][0])
                )
            ),
            action_low=parse_bound(header.get("action_low", -1.0)),
            action_high=parse_bound(header.get("action_high", 1.0)),
            provenance=header.get("provenance", {}),
            extra=extra,
        )
    except (TypeError, ValueError) as e:
        raise ElicitError(f"malformed demos header ({e})", path) from e
    check_episode_count(header, demos.episode, path)
    policy = bounds or header.get("action_bounds_policy", "error")
    if policy not in ("error", "warn", "clip"):
        raise ElicitError(f"unknown action bounds policy {policy!r}", path)
    return validate(demos, str(path), bounds=policy)


__all__ = [
    "CORE_COLUMNS",
    "DEMOS_KIND",
    "DEMOS_SCHEMA_VERSION",
    "SOURCE_EPISODE",
    "TASK_COLUMN",
    "BoundsPolicy",
    "Demos",
    "DemosWarning",
    "ObsField",
    "check_demos_layout",
    "check_episode_count",
    "concat_demos",
    "episode_digest",
    "fields_from_sizes",
    "from_episodes",
    "make_provenance",
    "read_demos",
    "read_demos_header",
    "validate",
    "write_demos",
]
