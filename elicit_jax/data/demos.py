"""The demonstration artifact: one Parquet row per step, episodes contiguous.

Columns: ``episode`` (int64), ``operator`` (string), ``step`` (int32, 0..T-1 per episode),
``obs`` (fixed-size list<float32>[obs_dim]), ``action`` (fixed-size list<float32>[act_dim]),
``reward`` (float32), ``success`` (bool, the episode's outcome), plus optional extra columns.
The header (schema metadata, see :mod:`elicit_jax.artifact`) holds the schema version,
dimensions, observation field slices, task name, action bounds and provenance.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np

from elicit_jax.artifact import make_header, read_header, write_parquet
from elicit_jax.errors import ElicitError

DEMOS_KIND = "demos"
DEMOS_SCHEMA_VERSION = 1
CORE_COLUMNS = ("episode", "operator", "step", "obs", "action", "reward", "success")
BoundsPolicy = Literal["error", "warn", "clip"]


@dataclasses.dataclass(frozen=True)
class ObsField:
    """A named slice of the observation vector, e.g. ``robot0_eef_pos`` = ``obs[:, 0:3]``."""

    name: str
    start: int
    stop: int

    @property
    def size(self) -> int:
        return self.stop - self.start


def fields_from_sizes(sizes: Sequence[tuple[str, int]]) -> tuple[ObsField, ...]:
    """Contiguous fields from ``(name, size)`` pairs, in order."""
    out, start = [], 0
    for name, size in sizes:
        out.append(ObsField(name, start, start + int(size)))
        start += int(size)
    return tuple(out)


@dataclasses.dataclass(frozen=True)
class Demos:
    """A set of demonstrations held as flat per-step arrays (N steps in all).

    Attributes:
      obs: (N, obs_dim) float32.
      action: (N, act_dim) float32.
      episode: (N,) int64 episode ids; each episode's rows are contiguous.
      operator: (N,) str operator name of each step's episode.
      step: (N,) int32 step index within the episode, 0..T-1.
      reward: (N,) float32.
      success: (N,) bool, the episode's outcome repeated on each of its steps.
      task: task name.
      obs_fields: named slices of ``obs``.
      action_low: lower action bound (scalar or per dim).
      action_high: upper action bound (scalar or per dim).
      provenance: where the data came from (source, its sha256, importer, time).
      extra: optional extra per-step columns, name -> (N, ...) array.
    """

    obs: np.ndarray
    action: np.ndarray
    episode: np.ndarray
    operator: np.ndarray
    step: np.ndarray
    reward: np.ndarray
    success: np.ndarray
    task: str = "unknown"
    obs_fields: tuple[ObsField, ...] = ()
    action_low: float | tuple[float, ...] = -1.0
    action_high: float | tuple[float, ...] = 1.0
    provenance: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    extra: Mapping[str, np.ndarray] = dataclasses.field(default_factory=dict)

    @property
    def obs_dim(self) -> int:
        return int(self.obs.shape[1])

    @property
    def action_dim(self) -> int:
        return int(self.action.shape[1])

    @property
    def n_steps(self) -> int:
        return int(self.obs.shape[0])

    def episode_bounds(self) -> list[tuple[int, int, int]]:
        """``(episode_id, start, stop)`` of each episode, in row order."""
        if self.n_steps == 0:
            return []
        change = np.flatnonzero(np.diff(self.episode)) + 1
        starts = np.concatenate([[0], change])
        stops = np.concatenate([change, [self.n_steps]])
        return [(int(self.episode[s]), int(s), int(e)) for s, e in zip(starts, stops, strict=True)]

    @property
    def episode_ids(self) -> np.ndarray:
        return np.array([e for e, _, _ in self.episode_bounds()], dtype=np.int64)

    @property
    def n_episodes(self) -> int:
        return len(self.episode_bounds())

    def episode_operator(self) -> dict[int, str]:
        """Episode id -> operator name."""
        return {e: str(self.operator[s]) for e, s, _ in self.episode_bounds()}

    def select(self, mask: np.ndarray) -> Demos:
        """Rows where ``mask`` (N,) is true; metadata kept."""
        mask = np.asarray(mask, dtype=bool)
        arrays = {k: getattr(self, k)[mask] for k in _ARRAY_FIELDS}
        extra = {k: v[mask] for k, v in self.extra.items()}
        return dataclasses.replace(self, **arrays, extra=extra)

    def select_episodes(self, ids: Sequence[int] | np.ndarray) -> Demos:
        """The given episodes, in their original order."""
        return self.select(np.isin(self.episode, np.asarray(ids, dtype=np.int64)))

    def select_operators(self, names: Sequence[str]) -> Demos:
        """Episodes of the given operators."""
        return self.select(np.isin(self.operator.astype(str), list(names)))

    def episodes(self) -> list[dict[str, np.ndarray]]:
        """Per-episode dicts of arrays (obs, action, reward, ...)."""
        out = []
        for _, s, e in self.episode_bounds():
            ep = {k: getattr(self, k)[s:e] for k in _ARRAY_FIELDS}
            ep.update({k: v[s:e] for k, v in self.extra.items()})
            out.append(ep)
        return out


_ARRAY_FIELDS = ("obs", "action", "episode", "operator", "step", "reward", "success")


def concat_demos(parts: Sequence[Demos], renumber: bool = True) -> Demos:
    """Concatenate demo sets of equal dims; episode ids renumbered 0..E-1 when ``renumber``."""
    if not parts:
        raise ElicitError("nothing to concatenate: no demonstration sets given")
    first = parts[0]
    for p in parts[1:]:
        if (p.obs_dim, p.action_dim) != (first.obs_dim, first.action_dim):
            raise ElicitError(
                f"cannot combine demos of dims obs={p.obs_dim}, act={p.action_dim} with "
                f"obs={first.obs_dim}, act={first.action_dim}"
            )
    arrays = {k: np.concatenate([getattr(p, k) for p in parts]) for k in _ARRAY_FIELDS}
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
    return dataclasses.replace(first, **arrays, extra=extra)


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
    if isinstance(operators, str):
        operators = [operators] * n
    successes = [True] * n if successes is None else list(successes)
    ids = list(range(n)) if episode_ids is None else list(episode_ids)
    cols: dict[str, list[np.ndarray]] = {k: [] for k in _ARRAY_FIELDS}
    extra_keys = (
        sorted(set.intersection(*(set(ep) for ep in episodes)) - {"obs", "action", "reward"})
        if n
        else []
    )
    extra: dict[str, list[np.ndarray]] = {k: [] for k in extra_keys}
    for i, ep in enumerate(episodes):
        t = len(ep["obs"])
        cols["obs"].append(np.asarray(ep["obs"], np.float32).reshape(t, -1))
        cols["action"].append(np.asarray(ep["action"], np.float32).reshape(t, -1))
        cols["reward"].append(np.asarray(ep.get("reward", np.zeros(t)), np.float32))
        cols["episode"].append(np.full(t, ids[i], np.int64))
        cols["operator"].append(np.full(t, operators[i], dtype=object))
        cols["step"].append(np.arange(t, dtype=np.int32))
        cols["success"].append(np.full(t, bool(successes[i])))
        for k in extra_keys:
            extra[k].append(np.asarray(ep[k]))
    if n == 0:
        raise ElicitError("no episodes to build a demonstration set from")
    arrays = {k: np.concatenate(v) for k, v in cols.items()}
    return Demos(**arrays, extra={k: np.concatenate(v) for k, v in extra.items()}, **meta)


def _to_table(demos: Demos) -> Any:
    import pyarrow as pa

    def fixed(arr: np.ndarray) -> pa.Array:
        arr = np.ascontiguousarray(arr, dtype=np.float32)
        return pa.FixedSizeListArray.from_arrays(pa.array(arr.reshape(-1)), arr.shape[1])

    cols = {
        "episode": pa.array(demos.episode.astype(np.int64)),
        "operator": pa.array(demos.operator.astype(str).tolist(), type=pa.string()),
        "step": pa.array(demos.step.astype(np.int32)),
        "obs": fixed(demos.obs),
        "action": fixed(demos.action),
        "reward": pa.array(demos.reward.astype(np.float32)),
        "success": pa.array(demos.success.astype(bool)),
    }
    for k, v in demos.extra.items():
        v = np.asarray(v)
        cols[k] = fixed(v) if v.ndim == 2 else pa.array(v)
    return pa.table(cols)


def write_demos(
    path: str | Path,
    demos: Demos,
    *,
    config: Mapping[str, Any] | None = None,
    inputs: Mapping[str, str | Path] | None = None,
    seed: int | None = None,
) -> None:
    """Validate and atomically write ``demos`` to a Parquet artifact."""
    validate(demos, str(path))
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
        provenance=dict(demos.provenance),
        n_episodes=demos.n_episodes,
        n_steps=demos.n_steps,
        extra_columns=sorted(demos.extra),
    )
    write_parquet(path, _to_table(demos), header)


def read_demos(path: str | Path, *, bounds: BoundsPolicy = "error") -> Demos:
    """Read and validate a demonstration artifact.

    Args:
      path: the Parquet file.
      bounds: what to do with actions outside their declared bounds: ``error`` (default),
        ``warn`` or ``clip``.

    Raises:
      ElicitError: one line naming the file (and episode/step) of the first problem found.
    """
    import pyarrow.parquet as pq

    header = read_header(path)
    if header.get("kind") != DEMOS_KIND:
        raise ElicitError(f"is a '{header.get('kind')}' artifact, expected demonstrations", path)
    if int(header.get("schema_version", -1)) > DEMOS_SCHEMA_VERSION:
        raise ElicitError(
            f"schema version {header['schema_version']} is newer than this elicit-jax "
            f"understands ({DEMOS_SCHEMA_VERSION}); upgrade elicit-jax",
            path,
        )
    table = pq.read_table(path)
    missing = [c for c in CORE_COLUMNS if c not in table.column_names]
    if missing:
        raise ElicitError(f"missing column(s) {', '.join(missing)}", path)
    obs = _fixed_to_numpy(table, "obs", path)
    action = _fixed_to_numpy(table, "action", path)
    for name, arr, key in (("obs", obs, "obs_dim"), ("action", action, "action_dim")):
        if key in header and arr.shape[1] != int(header[key]):
            raise ElicitError(
                f"column '{name}' has width {arr.shape[1]} but header says {key}={header[key]}",
                path,
            )
    extra = {}
    for k in header.get("extra_columns", []):
        if k in table.column_names:
            col = table.column(k)
            extra[k] = (
                _fixed_to_numpy(table, k, path)
                if col.type.num_fields == 0 and hasattr(col.type, "list_size")
                else col.to_numpy(zero_copy_only=False)
            )
    demos = Demos(
        obs=obs,
        action=action,
        episode=table.column("episode").to_numpy().astype(np.int64),
        operator=np.asarray(table.column("operator").to_pylist(), dtype=object),
        step=table.column("step").to_numpy().astype(np.int32),
        reward=table.column("reward").to_numpy().astype(np.float32),
        success=table.column("success").to_numpy(zero_copy_only=False).astype(bool),
        task=str(header.get("task", "unknown")),
        obs_fields=tuple(
            ObsField(n, int(a), int(b)) for n, (a, b) in header.get("obs_fields", {}).items()
        ),
        action_low=_bound(header.get("action_low", -1.0)),
        action_high=_bound(header.get("action_high", 1.0)),
        provenance=header.get("provenance", {}),
        extra=extra,
    )
    if (
        "n_episodes" in header
        and demos.n_steps
        and int(header["n_episodes"]) != len(np.unique(demos.episode))
    ):
        raise ElicitError(
            f"header lists {header['n_episodes']} episodes but the file holds "
            f"{len(np.unique(demos.episode))} (an empty or truncated episode?)",
            path,
        )
    return validate(demos, str(path), bounds=bounds)


def _bound(v: Any) -> float | tuple[float, ...]:
    return tuple(float(x) for x in v) if isinstance(v, list | tuple) else float(v)


def _fixed_to_numpy(table: Any, name: str, path: Any) -> np.ndarray:
    import pyarrow as pa

    col = table.column(name).combine_chunks()
    if not pa.types.is_fixed_size_list(col.type):
        raise ElicitError(
            f"column '{name}' must be a fixed-size list of float32, got {col.type}", path
        )
    if col.null_count:
        raise ElicitError(f"column '{name}' has {col.null_count} null rows", path)
    width = col.type.list_size
    return col.flatten().to_numpy(zero_copy_only=False).astype(np.float32).reshape(-1, width)


def validate(demos: Demos, source: str = "<demos>", bounds: BoundsPolicy = "error") -> Demos:
    """Check a :class:`Demos` for consistency; returns it (clipped if ``bounds='clip'``).

    Checks: matching row counts, 2-D obs/action, finite values, at least one episode,
    contiguous episodes, steps 0..T-1 in order, obs fields within obs_dim, actions within
    their declared bounds.
    """
    n = demos.obs.shape[0]
    if demos.obs.ndim != 2 or demos.action.ndim != 2:
        raise ElicitError(
            f"obs and action must be 2-D, got {demos.obs.shape} and {demos.action.shape}", source
        )
    for k in _ARRAY_FIELDS:
        if len(getattr(demos, k)) != n:
            raise ElicitError(
                f"column '{k}' has {len(getattr(demos, k))} rows, expected {n}", source
            )
    if n == 0:
        raise ElicitError("holds no steps (empty demonstration set)", source)
    for name in ("obs", "action", "reward"):
        arr = getattr(demos, name)
        bad = ~np.isfinite(arr)
        if bad.any():
            row = int(np.argwhere(bad)[0][0])
            raise ElicitError(
                f"non-finite {name} value at episode {demos.episode[row]}, step {demos.step[row]}",
                source,
            )
    bounds_list = demos.episode_bounds()
    ids = [e for e, _, _ in bounds_list]
    if len(ids) != len(set(ids)):
        dup = next(e for e in ids if ids.count(e) > 1)
        raise ElicitError(f"episode {dup} is not contiguous (its rows are split)", source)
    for e, s, stop in bounds_list:
        steps = demos.step[s:stop]
        expect = np.arange(stop - s)
        if not np.array_equal(steps, expect):
            i = int(np.flatnonzero(steps != expect)[0])
            raise ElicitError(
                f"episode {e}: steps must run 0..{stop - s - 1} in order, "
                f"found {steps[i]} at position {i}",
                source,
            )
    for f in demos.obs_fields:
        if not 0 <= f.start < f.stop <= demos.obs_dim:
            raise ElicitError(
                f"obs field '{f.name}' {f.start}:{f.stop} lies outside obs_dim {demos.obs_dim}",
                source,
            )
    lo = np.broadcast_to(np.asarray(demos.action_low, np.float32), (demos.action_dim,))
    hi = np.broadcast_to(np.asarray(demos.action_high, np.float32), (demos.action_dim,))
    out = (demos.action < lo - 1e-6) | (demos.action > hi + 1e-6)
    if out.any():
        row, dim = (int(x) for x in np.argwhere(out)[0])
        msg = (
            f"action[{dim}] = {demos.action[row, dim]:.4g} outside bounds "
            f"[{lo[dim]:.4g}, {hi[dim]:.4g}] at episode {demos.episode[row]}, "
            f"step {demos.step[row]} "
            f"({int(out.any(axis=1).sum())} steps in all)"
        )
        if bounds == "error":
            raise ElicitError(msg + "; pass --clip-actions or --warn-actions to accept", source)
        if bounds == "warn":
            warnings.warn(f"{source}: {msg}", stacklevel=2)
        else:
            demos = dataclasses.replace(demos, action=np.clip(demos.action, lo, hi))
    return demos
