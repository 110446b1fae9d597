"""Write a selection of a local LeRobot dataset's episodes as a new dataset folder.

The new folder keeps every tabular frame column of the source, renumbers the chosen episodes
0..k-1 (in source order) and the global ``index`` 0..N-1, and rebuilds the metadata for the
requested codebase version (v2.1 or v3.0): ``info.json``, episodes, tasks and statistics.
Datasets with video features are refused (their mp4 files would need re-cutting).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import atomic_path, dumps
from elicit_jax.data.lerobot import (
    V2_DATA_PATH,
    V3_DATA_PATH,
    V3_EPISODES_PATH,
    load_frames,
    read_episodes,
    read_info,
    read_tasks,
    select_rows,
    split_episodes,
)
from elicit_jax.errors import ElicitError

EXPORT_VERSIONS = ("v2.1", "v3.0")


def _numeric_features(info: dict[str, Any], table: Any) -> list[str]:
    return [
        k
        for k, ft in info["features"].items()
        if k in table.column_names and ft.get("dtype") not in ("video", "image", "string")
    ]


def _stats(table: Any, name: str) -> dict[str, list[float]]:
    """LeRobot-style per-feature stats over a table's rows: min, max, mean, std, count."""
    import pyarrow as pa

    col = table.column(name).combine_chunks()
    if pa.types.is_list(col.type) or pa.types.is_fixed_size_list(col.type):
        arr = col.flatten().to_numpy(zero_copy_only=False).astype(np.float64)
        arr = arr.reshape(len(col), -1)
    else:
        arr = col.to_numpy(zero_copy_only=False).astype(np.float64).reshape(-1, 1)
    return {
        "min": arr.min(0).tolist(),
        "max": arr.max(0).tolist(),
        "mean": arr.mean(0).tolist(),
        "std": arr.std(0).tolist(),
        "count": [len(arr)],
    }


def _gather(source: Path, info: dict[str, Any], episodes: Sequence[int]) -> tuple[Any, list]:
    """The chosen episodes' frames, renumbered, and their new metadata rows."""
    import pyarrow as pa

    rows = select_rows(source, read_episodes(source, info), episodes)
    by_episode = split_episodes(load_frames(source, info, rows, None), rows)
    parts, meta, start = [], [], 0
    for new, r in enumerate(rows):
        part = by_episode[int(r["episode_index"])][1]
        n = part.num_rows
        ep_type = part.schema.field("episode_index").type
        part = part.set_column(
            part.column_names.index("episode_index"),
            "episode_index",
            pa.array(np.full(n, new), ep_type),
        )
        if "index" in part.column_names:
            idx_type = part.schema.field("index").type
            part = part.set_column(
                part.column_names.index("index"),
                "index",
                pa.array(np.arange(start, start + n), idx_type),
            )
        parts.append(part)
        meta.append(
            {
                "episode_index": new,
                "tasks": list(r.get("tasks") or []),
                "length": n,
                "from": start,
                "to": start + n,
                "source_episode_index": int(r["episode_index"]),
            }
        )
        start += n
    return pa.concat_tables([p.cast(parts[0].schema) for p in parts]), meta


def _info(
    source_info: dict[str, Any], version: str, n_eps: int, n_frames: int, n_tasks: int
) -> dict:
    info = {k: v for k, v in source_info.items() if k not in ("total_chunks", "total_videos")}
    chunks = int(source_info.get("chunks_size", 1000))
    info.update(
        codebase_version=version,
        total_episodes=n_eps,
        total_frames=n_frames,
        total_tasks=n_tasks,
        chunks_size=chunks,
        splits={"train": f"0:{n_eps}"},
        data_path=V3_DATA_PATH if version == "v3.0" else V2_DATA_PATH,
        video_path=None,
    )
    if version == "v3.0":
        info.setdefault("data_files_size_in_mb", 100)
        info.setdefault("video_files_size_in_mb", 200)
    else:
        info.pop("data_files_size_in_mb", None)
        info.pop("video_files_size_in_mb", None)
        info.update(total_chunks=math.ceil(n_eps / chunks), total_videos=0)
    return info


def _jsonl(path: Path, rows: list[dict[str, Any]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))


def _write_v21(out: Path, table: Any, meta: list, tasks: dict[int, str], info: dict) -> None:
    import pyarrow.parquet as pq

    feats = _numeric_features(info, table)
    ep_rows, stat_rows = [], []
    for m in meta:
        part = table.slice(m["from"], m["length"])
        path = out / V2_DATA_PATH.format(
            episode_chunk=m["episode_index"] // info["chunks_size"],
            episode_index=m["episode_index"],
        )
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(part, path)
        ep_rows.append({k: m[k] for k in ("episode_index", "tasks", "length")})
        stat_rows.append(
            {"episode_index": m["episode_index"], "stats": {f: _stats(part, f) for f in feats}}
        )
    _jsonl(out / "meta" / "episodes.jsonl", ep_rows)
    _jsonl(out / "meta" / "episodes_stats.jsonl", stat_rows)
    _jsonl(
        out / "meta" / "tasks.jsonl",
        [{"task_index": i, "task": t} for i, t in sorted(tasks.items())],
    )


def _write_v30(out: Path, table: Any, meta: list, tasks: dict[int, str], info: dict) -> None:
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    feats = _numeric_features(info, table)
    path = out / V3_DATA_PATH.format(chunk_index=0, file_index=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(table, path)
    records = []
    for m in meta:
        part = table.slice(m["from"], m["length"])
        rec: dict[str, Any] = {
            "episode_index": m["episode_index"],
            "tasks": m["tasks"],
            "length": m["length"],
            "data/chunk_index": 0,
            "data/file_index": 0,
            "dataset_from_index": m["from"],
            "dataset_to_index": m["to"],
            "meta/episodes/chunk_index": 0,
            "meta/episodes/file_index": 0,
        }
        for f in feats:
            for metric, value in _stats(part, f).items():
                rec[f"stats/{f}/{metric}"] = value
        records.append(rec)
    ep_path = out / V3_EPISODES_PATH.format(chunk_index=0, file_index=0)
    ep_path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.Table.from_pylist(records), ep_path)
    order = sorted(tasks)
    df = pd.DataFrame({"task_index": order}, index=pd.Index([tasks[i] for i in order], name="task"))
    df.to_parquet(out / "meta" / "tasks.parquet")
    stats = {f: _stats(table, f) for f in feats}
    (out / "meta" / "stats.json").write_text(json.dumps(stats, indent=1) + "\n")


def export_lerobot(
    source: str | Path,
    out: str | Path,
    episodes: Sequence[int],
    *,
    version: str = "v2.1",
    header: dict[str, Any] | None = None,
) -> list[int]:
    """Write the chosen episodes of the dataset at ``source`` as a new folder ``out``.

    Args:
      source: a LeRobot dataset folder (v2.x or v3.0).
      out: the new folder (written atomically; replaced if it exists).
      episodes: source ``episode_index`` values to keep.
      version: codebase version of the new folder, ``v2.1`` or ``v3.0``.
      header: elicit-jax artifact header, stored as ``artifact.json`` at the folder's root.

    Returns:
      The source episode indices written, in order (new index = position).
    """
    source, out = Path(source), Path(out)
    if version not in EXPORT_VERSIONS:
        raise ElicitError(f"cannot write LeRobot codebase version {version!r} ({EXPORT_VERSIONS})")
    if out.resolve() == source.resolve():
        raise ElicitError("output must differ from the source dataset folder", out)
    info = read_info(source)
    videos = [k for k, ft in info["features"].items() if ft.get("dtype") == "video"]
    if videos:
        raise ElicitError(
            f"has video features ({', '.join(videos)}); export an episode list "
            "(-o selection.json) instead of a new folder",
            source,
        )
    tasks = read_tasks(source, info)
    table, meta = _gather(source, info, episodes)
    new_info = _info(info, version, len(meta), table.num_rows, len(tasks))
    with atomic_path(out) as tmp:
        tmp.mkdir()
        (tmp / "meta").mkdir()
        (tmp / "meta" / "info.json").write_text(json.dumps(new_info, indent=4) + "\n")
        writer = _write_v30 if version == "v3.0" else _write_v21
        writer(tmp, table, meta, tasks, new_info)
        if header is not None:
            (tmp / "artifact.json").write_text(dumps(header) + "\n")
    return [m["source_episode_index"] for m in meta]
