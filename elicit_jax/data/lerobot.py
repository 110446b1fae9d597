"""Local LeRobot dataset folders (codebase v2.0/v2.1 and v3.0): import and export episodes.

v2.x: ``meta/info.json`` (``codebase_version``, ``data_path`` template, ``chunks_size``,
``fps``, ``features``), ``meta/episodes.jsonl`` (``episode_index``, ``tasks``, ``length``),
``meta/tasks.jsonl`` (``task_index``, ``task``), ``meta/episodes_stats.jsonl``, and one
Parquet file per episode at ``data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}``.
v3.0: many episodes per ``data/chunk-XXX/file-YYY.parquet``; per-episode metadata (length,
tasks, data file, row range, stats) in ``meta/episodes/chunk-XXX/file-YYY.parquet``; tasks
in ``meta/tasks.parquet`` (index: task text, column ``task_index``); ``meta/stats.json``.
Frame columns: ``observation.state``, ``action``, ``episode_index``, ``frame_index``,
``index``, ``timestamp``, ``task_index``, optionally ``next.reward``/``next.done``/
``next.success``. No hub access: folders are read from disk.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import read_json
from elicit_jax.data.demos import (
    TASK_COLUMN,
    Demos,
    fields_from_sizes,
    from_episodes,
    make_provenance,
    validate,
)
from elicit_jax.data.lerobot_record import label_episodes, restored_provenance
from elicit_jax.errors import ElicitError

SUPPORTED_VERSIONS = ("v2.0", "v2.1", "v3.0")
V2_DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
V3_DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
V3_EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
DEFAULT_OBS_KEYS = ("observation.state",)
NON_TABULAR = ("video", "image", "string")


def read_info(root: str | Path) -> dict[str, Any]:
    """``meta/info.json`` of a dataset folder, checked for a supported codebase version."""
    root = Path(root)
    if root.is_file():
        raise ElicitError("is a file, not a LeRobot dataset folder", root)
    if not root.is_dir():
        raise ElicitError("not a LeRobot dataset folder (no such directory)", root)
    if not (root / "meta" / "info.json").is_file():
        raise ElicitError("not a LeRobot dataset folder (no meta/info.json)", root)
    info = read_json(root / "meta" / "info.json")
    version = info.get("codebase_version") if isinstance(info, dict) else None
    if version not in SUPPORTED_VERSIONS:
        raise ElicitError(
            f"meta/info.json: codebase_version {version!r} is not supported "
            f"({', '.join(SUPPORTED_VERSIONS)})",
            root,
        )
    if not isinstance(info.get("features"), dict):
        raise ElicitError("meta/info.json has no 'features' mapping", root)
    return info


def _is_v3(info: dict[str, Any]) -> bool:
    return str(info["codebase_version"]).startswith("v3")


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    if not path.is_file():
        raise ElicitError("missing file", path)
    rows = []
    for i, line in enumerate(path.read_text().splitlines(), start=1):
        if line.strip():
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError as e:
                raise ElicitError(f"line {i}: malformed JSON ({e.msg})", path) from e
    return rows


def _read_parquet(path: Path, columns: Sequence[str] | None = None) -> Any:
    import pyarrow.parquet as pq

    if not path.is_file():
        raise ElicitError("missing file", path)
    try:
        return pq.read_table(path, columns=None if columns is None else list(columns))
    except Exception as e:  # pyarrow raises several types for corrupt input or missing columns
        raise ElicitError(f"cannot read Parquet ({type(e).__name__}: {e})", path) from e


def read_tasks(root: str | Path, info: dict[str, Any]) -> dict[int, str]:
    """Task index -> task text."""
    root = Path(root)
    if _is_v3(info):
        import pyarrow.parquet as pq

        path = root / "meta" / "tasks.parquet"
        if not path.is_file():
            raise ElicitError("missing file", path)
        df = pq.read_table(path).to_pandas()
        if "task_index" not in df.columns:
            raise ElicitError("has no 'task_index' column", path)
        texts = df["task"] if "task" in df.columns else df.index
        return {int(i): str(t) for i, t in zip(df["task_index"], texts, strict=True)}
    return {int(r["task_index"]): str(r["task"]) for r in read_jsonl(root / "meta" / "tasks.jsonl")}


def read_episodes(root: str | Path, info: dict[str, Any]) -> list[dict[str, Any]]:
    """Per-episode metadata rows (``episode_index``, ``length``, ``tasks``, v3 locators)."""
    root = Path(root)
    if not _is_v3(info):
        rows = read_jsonl(root / "meta" / "episodes.jsonl")
    else:
        files = sorted((root / "meta" / "episodes").glob("chunk-*/file-*.parquet"))
        if not files:
            raise ElicitError("no meta/episodes/chunk-*/file-*.parquet", root)
        rows = []
        for path in files:
            rows.extend(_read_parquet(path).to_pylist())
    for r in rows:
        if "episode_index" not in r or "length" not in r:
            raise ElicitError("episode metadata without 'episode_index' or 'length'", root)
    return sorted(rows, key=lambda r: int(r["episode_index"]))


def _data_paths(root: Path, info: dict[str, Any], rows: list[dict[str, Any]]) -> list[Path]:
    template = info.get("data_path") or (V3_DATA_PATH if _is_v3(info) else V2_DATA_PATH)
    if _is_v3(info):
        keys = sorted({(int(r["data/chunk_index"]), int(r["data/file_index"])) for r in rows})
        return [root / template.format(chunk_index=c, file_index=f) for c, f in keys]
    size = int(info.get("chunks_size", 1000))
    return [
        root / template.format(episode_chunk=int(r["episode_index"]) // size, **r) for r in rows
    ]


def _to_matrix(col: Any, name: str, path: Path) -> np.ndarray:
    """A list, fixed-size-list or scalar Arrow column as (N, d) float32."""
    import pyarrow as pa
    import pyarrow.compute as pc

    col = col.combine_chunks() if hasattr(col, "combine_chunks") else col
    if col.null_count:
        raise ElicitError(f"column '{name}' has {col.null_count} null rows", path)
    if pa.types.is_list(col.type) or pa.types.is_large_list(col.type):
        widths = np.unique(pc.list_value_length(col).to_numpy())
        if len(widths) > 1:
            raise ElicitError(f"column '{name}' has rows of widths {widths.tolist()}", path)
        return col.flatten().to_numpy(zero_copy_only=False).astype(np.float32).reshape(len(col), -1)
    if pa.types.is_fixed_size_list(col.type):
        width = col.type.list_size
        return col.flatten().to_numpy(zero_copy_only=False).astype(np.float32).reshape(-1, width)
    if (
        pa.types.is_integer(col.type)
        or pa.types.is_floating(col.type)
        or pa.types.is_boolean(col.type)
    ):
        return col.to_numpy(zero_copy_only=False).astype(np.float32).reshape(-1, 1)
    raise ElicitError(f"column '{name}' has unsupported type {col.type}", path)


def load_frames(
    root: Path,
    info: dict[str, Any],
    rows: list[dict[str, Any]],
    columns: Sequence[str] | None,
    optional: Sequence[str] = (),
) -> list[tuple[Path, Any]]:
    """(file, table) of every data file holding the given episodes.

    ``columns`` must exist (``None``: read every column); ``optional`` ones are read if present.
    """
    import pyarrow.parquet as pq

    out = []
    for path in _data_paths(root, info, rows):
        if not path.is_file():
            raise ElicitError("missing data file", path)
        try:
            names = pq.read_schema(path).names
        except Exception as e:  # pyarrow raises several types for corrupt input
            raise ElicitError(f"cannot read Parquet ({type(e).__name__}: {e})", path) from e
        cols = None
        if columns is not None:
            missing = [c for c in columns if c not in names]
            if missing:
                raise ElicitError(f"missing column(s) {', '.join(missing)}", path)
            cols = [*columns, *(c for c in optional if c in names and c not in columns)]
        out.append((path, _read_parquet(path, cols)))
    return out


def split_episodes(
    frames: list[tuple[Path, Any]], rows: list[dict[str, Any]]
) -> dict[int, tuple[Path, Any]]:
    """Episode index -> (file, table slice) with frames in file order; checks frame indices."""
    wanted = {int(r["episode_index"]): int(r["length"]) for r in rows}
    found: dict[int, tuple[Path, Any]] = {}
    for path, table in frames:
        ep = table.column("episode_index").to_numpy()
        for e in np.unique(ep):
            e = int(e)
            if e not in wanted:
                continue
            idx = np.flatnonzero(ep == e)
            if e in found or idx[-1] - idx[0] + 1 != len(idx):
                raise ElicitError(f"episode {e}: its frames are not contiguous", path)
            part = table.slice(int(idx[0]), len(idx))
            frame = part.column("frame_index").to_numpy()
            if not np.array_equal(frame, np.arange(len(idx))):
                i = int(np.flatnonzero(frame != np.arange(len(idx)))[0])
                raise ElicitError(
                    f"episode {e}: frame_index must run 0..{len(idx) - 1}, found {frame[i]} "
                    f"at frame {i}",
                    path,
                )
            if len(idx) != wanted[e]:
                raise ElicitError(
                    f"episode {e}: metadata says {wanted[e]} frames, data has {len(idx)}", path
                )
            found[e] = (path, part)
    for e in wanted:
        if e not in found:
            raise ElicitError(f"episode {e} is listed in meta but has no frames", frames[0][0])
    return found


def select_rows(
    root: Path, rows: list[dict[str, Any]], episodes: Sequence[int] | None
) -> list[dict[str, Any]]:
    if episodes is None:
        return rows
    by_index = {int(r["episode_index"]): r for r in rows}
    missing = [e for e in episodes if int(e) not in by_index]
    if missing:
        raise ElicitError(f"has no episode {missing[0]}", root)
    if not episodes:
        raise ElicitError("no episodes selected", root)
    return [by_index[e] for e in sorted({int(e) for e in episodes})]


def frame_tasks(part: Any, row: dict[str, Any], tasks: dict[int, str]) -> np.ndarray:
    """Each frame's task text: from its ``task_index`` (LeRobot records one per frame), else
    the episode's one listed task (several listed without frame indices: joined)."""
    if "task_index" in part.column_names:
        index = part.column("task_index").to_numpy(zero_copy_only=False)
        texts = {int(i): tasks.get(int(i), "unknown") for i in np.unique(index)}
        return np.array([texts[int(i)] for i in index], dtype=object)
    listed = [str(t) for t in row.get("tasks") or []] or ["unknown"]
    return np.full(part.num_rows, " | ".join(listed), dtype=object)


def import_lerobot(
    root: str | Path,
    *,
    obs_keys: Sequence[str] | None = None,
    operator: str = "unknown",
    task: str | None = None,
    episodes: Sequence[int] | None = None,
    action_bounds: tuple[float, float] | None = None,
    finite: bool = True,
) -> Demos:
    """Read a local LeRobot dataset folder into :class:`Demos`.

    Args:
      root: the dataset folder (holding ``meta/`` and ``data/``).
      obs_keys: frame features concatenated into ``obs``; default ``observation.state``.
      operator: operator label of every episode.
      task: task name; default the dataset's task text(s).
      episodes: episode indices to import (default all).
      action_bounds: declared action bounds; ``None`` takes each dimension's min/max over
        the data (LeRobot actions are often joint targets, not in [-1, 1]).
      finite: reject non-finite values here (False: the caller skips such episodes).

    Outcome: any ``next.success`` if that column exists, else assumed successful. Rewards:
    ``next.reward`` if present, else 0. Each frame's task text goes to the ``task`` column.
    A folder written by ``elicit-jax export`` gives back what its record holds
    (:mod:`.lerobot_record`: operators unless ``operator`` is given, names, ``env_args``...).
    """
    root = Path(root)
    obs_keys = tuple(obs_keys or DEFAULT_OBS_KEYS)
    info = read_info(root)
    _check_features(root, info, obs_keys)
    all_rows = read_episodes(root, info)
    rows = select_rows(root, all_rows, episodes)
    if not rows:
        raise ElicitError("dataset lists no episodes", root)
    tasks = read_tasks(root, info)
    eps, successes, sizes, has_success = _read_frames(root, info, rows, obs_keys, tasks)
    labels, names, digests = label_episodes(
        root,
        info,
        rows,
        all_rows,
        obs_keys,
        eps,
        lambda k: _read_frames(root, info, rows, k, tasks)[0],
    )
    fields = fields_from_sizes(list(zip(obs_keys, sizes, strict=True)))
    bounds_from = "data min/max" if action_bounds is None else "given"
    restored: dict[str, Any] = {}
    if labels is not None:
        if operator == "unknown":
            operator = [labels["operators"][int(r["episode_index"])] for r in rows]
        if action_bounds is None and "action_low" in labels:
            action_bounds = (labels["action_low"], labels["action_high"])
            bounds_from = labels["from"]
        if "obs_fields" in labels and labels["obs_fields"][-1].stop == fields[-1].stop:
            fields = labels["obs_fields"]
        restored = restored_provenance(labels, names)
    low, high = _bounds(eps, action_bounds)
    texts = np.concatenate([ep[TASK_COLUMN] for ep in eps])
    demos = from_episodes(
        eps,
        operators=operator,
        successes=successes,
        task=task or " | ".join(dict.fromkeys(str(t) for t in texts)),
        obs_fields=fields,
        action_low=low,
        action_high=high,
        provenance=make_provenance(
            root,
            "lerobot",
            codebase_version=info["codebase_version"],
            fps=info.get("fps"),
            obs_keys=list(obs_keys),
            action_bounds_from=bounds_from,
            success_from="next.success" if has_success else "assumed (no next.success)",
            labels_from=labels["from"] if labels is not None else None,
            episode_sha256=digests,
            **restored,
        ),
    )
    return validate(demos, str(root), bounds=None, finite=finite)


def _bounds(eps: list[dict[str, np.ndarray]], given: Any) -> tuple[Any, Any]:
    """Declared action bounds: ``given``, else each dimension's min/max over the data."""
    if given is None:
        actions = np.concatenate([ep["action"] for ep in eps])
        given = (np.nanmin(actions, 0).tolist(), np.nanmax(actions, 0).tolist())
    return tuple(tuple(b) if isinstance(b, list | tuple) else float(b) for b in given)  # type: ignore[return-value]


def _check_features(root: Path, info: dict[str, Any], obs_keys: Sequence[str]) -> None:
    for key in (*obs_keys, "action"):
        if key not in info["features"]:
            raise ElicitError(
                f"meta/info.json has no feature '{key}' (features: "
                f"{', '.join(sorted(info['features']))})",
                root,
            )
        if info["features"][key].get("dtype") in NON_TABULAR:
            raise ElicitError(f"feature '{key}' is a {info['features'][key]['dtype']}", root)


def _read_frames(
    root: Path,
    info: dict[str, Any],
    rows: list[dict[str, Any]],
    obs_keys: Sequence[str],
    tasks: dict[int, str],
) -> tuple[list[dict[str, np.ndarray]], list[bool], list[int], bool]:
    """Episodes (obs, action, reward, frame tasks), outcomes, obs key widths and whether the
    outcomes were recorded (``next.success``)."""
    columns = (*obs_keys, "action", "episode_index", "frame_index")
    optional = ("next.reward", "next.success", "task_index")
    by_episode = split_episodes(load_frames(root, info, rows, columns, optional), rows)
    eps, successes, sizes = [], [], []
    has_success = all("next.success" in t.column_names for _, t in by_episode.values())
    for r in rows:
        e = int(r["episode_index"])
        path, part = by_episode[e]
        mats = [_to_matrix(part.column(k), k, path) for k in obs_keys]
        sizes = sizes or [m.shape[1] for m in mats]
        ep = {
            "obs": np.concatenate(mats, axis=1),
            "action": _to_matrix(part.column("action"), "action", path),
            TASK_COLUMN: frame_tasks(part, r, tasks),
        }
        if "next.reward" in part.column_names:
            ep["reward"] = _to_matrix(part.column("next.reward"), "next.reward", path)[:, 0]
        eps.append(ep)
        successes.append(
            bool(_to_matrix(part.column("next.success"), "next.success", path).any())
            if has_success
            else True
        )
    if any("reward" not in ep for ep in eps):
        for ep in eps:
            ep.pop("reward", None)
    return eps, successes, sizes, has_success
