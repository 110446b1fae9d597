"""Write a LeRobot dataset folder (codebase v2.1 or v3.0) from frames and episode metadata.

Both exporters (a selection of a source dataset, :mod:`elicit_jax.data.lerobot_export`, and
a new dataset from any demonstrations, :mod:`elicit_jax.data.lerobot_fresh`) hand this
module a frame table (already renumbered: ``episode_index`` 0..E-1 in order, ``index``
0..N-1), one metadata row per episode and the new ``info.json``; it writes the files LeRobot
reads and the statistics LeRobot computes (:mod:`elicit_jax.data.lerobot_stats`):

* v3.0 (LeRobot 0.4 and later): ``data/chunk-000/file-000.parquet`` (one row group per
  episode), ``meta/episodes/chunk-000/file-000.parquet`` (locators and ``stats/<feature>/<key>``
  columns), ``meta/tasks.parquet``, ``meta/stats.json``;
* v2.1 (LeRobot 0.1-0.3): one ``data/chunk-XXX/episode_XXXXXX.parquet`` per episode,
  ``meta/episodes.jsonl``, ``meta/episodes_stats.jsonl``, ``meta/tasks.jsonl``,
  ``meta/stats.json``.

Video files are the caller's: it copies them and puts their locators in the episode rows.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.data.lerobot import V2_DATA_PATH, V3_DATA_PATH, V3_EPISODES_PATH
from elicit_jax.data.lerobot_stats import Stats, aggregate_stats, feature_stats, to_json

EXPORT_VERSIONS = ("v2.1", "v3.0")
CURRENT_VERSION = "v3.0"
V2_VIDEO_PATH = "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"
V3_VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
CAMERA_DTYPES = ("video", "image")
NO_STATS_DTYPES = ("video", "image", "string", "language")


CONVERT_V21 = (
    "python -m lerobot.scripts.convert_dataset_v21_to_v30 --repo-id=REPO_ID --root={out} "
    "--push-to-hub=false"
)


def version_notes(source_version: str, version: str, out: str | Path) -> list[str]:
    """What to know about the codebase version written (LeRobot 0.4 and later read v3.0 only)."""
    if version != CURRENT_VERSION:
        return [
            f"written as {version}, which LeRobot 0.4 and later refuse (BackwardCompatibility"
            f"Error); use it with LeRobot 0.1-0.3, or convert it: {CONVERT_V21.format(out=out)}"
        ]
    if not str(source_version).startswith("v3"):
        return [
            f"the source is {source_version}; written as {CURRENT_VERSION}, the version "
            "LeRobot 0.4 and later read (pass --version v2.1 to keep the old layout)"
        ]
    return []


def camera_keys(info: Mapping[str, Any]) -> list[str]:
    """Features holding images or videos."""
    return [k for k, ft in info["features"].items() if ft.get("dtype") in CAMERA_DTYPES]


def video_keys(info: Mapping[str, Any]) -> list[str]:
    return [k for k, ft in info["features"].items() if ft.get("dtype") == "video"]


def column_values(table: Any, name: str) -> np.ndarray:
    """A frame column in its stored dtype: ``(N,)`` for scalars, ``(N, d)`` for vectors."""
    import pyarrow as pa

    col = table.column(name).combine_chunks()
    if pa.types.is_list(col.type) or pa.types.is_fixed_size_list(col.type):
        flat = col.flatten().to_numpy(zero_copy_only=False)
        return flat.reshape(len(col), -1)
    return col.to_numpy(zero_copy_only=False)


def finish_info(
    base: Mapping[str, Any], version: str, n_episodes: int, n_frames: int, n_tasks: int
) -> dict[str, Any]:
    """``info.json`` for ``version`` from ``base`` (features, fps, robot type, chunk size)."""
    info = {
        k: v
        for k, v in base.items()
        if k
        not in (
            "total_chunks",
            "total_videos",
            "data_files_size_in_mb",
            "video_files_size_in_mb",
            "elicit_jax",  # the source's record: the exporter writes the new folder's
        )
    }
    chunks = int(base.get("chunks_size") or 1000)
    has_video = bool(video_keys(info))
    info.update(
        codebase_version=version,
        total_episodes=n_episodes,
        total_frames=n_frames,
        total_tasks=n_tasks,
        chunks_size=chunks,
        splits={"train": f"0:{n_episodes}"},
    )
    if version == "v3.0":
        info.update(
            data_files_size_in_mb=int(base.get("data_files_size_in_mb") or 100),
            video_files_size_in_mb=int(base.get("video_files_size_in_mb") or 200),
            data_path=V3_DATA_PATH,
            video_path=V3_VIDEO_PATH if has_video else None,
        )
    else:
        info.update(
            total_chunks=math.ceil(n_episodes / chunks),
            total_videos=n_episodes * len(video_keys(info)),
            data_path=V2_DATA_PATH,
            video_path=V2_VIDEO_PATH if has_video else None,
        )
    return info


def episode_stats(
    table: Any, info: Mapping[str, Any], episodes: Sequence[Mapping[str, Any]]
) -> list[dict[str, Stats]]:
    """Per-episode statistics of every numeric frame feature (cameras are the caller's)."""
    feats = [
        k
        for k, ft in info["features"].items()
        if k in table.column_names and ft.get("dtype") not in NO_STATS_DTYPES
    ]
    values = {f: column_values(table, f) for f in feats}
    return [{f: feature_stats(v[m["from"] : m["to"]]) for f, v in values.items()} for m in episodes]


def _write_frames(path: Path, table: Any, episodes: Sequence[Mapping[str, Any]]) -> None:
    """One Parquet file, one row group per episode (as LeRobot's recorder writes them)."""
    import pyarrow.parquet as pq

    path.parent.mkdir(parents=True, exist_ok=True)
    with pq.ParquetWriter(path, table.schema, compression="snappy") as writer:
        for m in episodes:
            writer.write_table(table.slice(m["from"], m["length"]))


def _jsonl(path: Path, rows: list[dict[str, Any]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))


def write_folder(
    out: Path,
    table: Any,
    episodes: Sequence[Mapping[str, Any]],
    tasks: Mapping[int, str],
    info: Mapping[str, Any],
    camera_stats: Sequence[Mapping[str, Stats]] | None = None,
) -> dict[str, Stats]:
    """Write a dataset folder's frames and metadata; returns the dataset statistics.

    Args:
      out: the (empty, existing) folder.
      table: all frames, episodes contiguous and renumbered.
      episodes: per episode ``episode_index``, ``tasks``, ``length``, ``from``, ``to`` and,
        for v3.0, any extra locator columns (``videos/<key>/...``).
      tasks: task index -> text.
      info: the new ``info.json`` (see :func:`finish_info`).
      camera_stats: per episode, statistics of each camera feature (carried from the source).
    """
    per_episode = episode_stats(table, info, episodes)
    for i, cams in enumerate(camera_stats or []):
        per_episode[i].update(cams)
    features = list(per_episode[0]) if per_episode else []
    stats = {f: aggregate_stats([s[f] for s in per_episode]) for f in features}
    (out / "meta").mkdir(parents=True, exist_ok=True)
    (out / "meta" / "info.json").write_text(json.dumps(dict(info), indent=4) + "\n")
    (out / "meta" / "stats.json").write_text(json.dumps(to_json(stats), indent=4) + "\n")
    if info["codebase_version"] == "v3.0":
        _write_v30(out, table, episodes, tasks, per_episode)
    else:
        _write_v21(out, table, episodes, tasks, per_episode, int(info["chunks_size"]))
    return stats


def _write_v21(out, table, episodes, tasks, per_episode, chunks_size) -> None:
    ep_rows, stat_rows = [], []
    for m, st in zip(episodes, per_episode, strict=True):
        e = int(m["episode_index"])
        path = out / V2_DATA_PATH.format(episode_chunk=e // chunks_size, episode_index=e)
        _write_frames(path, table, [m])
        ep_rows.append({"episode_index": e, "tasks": list(m["tasks"]), "length": m["length"]})
        stat_rows.append({"episode_index": e, "stats": to_json(st)})
    _jsonl(out / "meta" / "episodes.jsonl", ep_rows)
    _jsonl(out / "meta" / "episodes_stats.jsonl", stat_rows)
    _jsonl(
        out / "meta" / "tasks.jsonl", [{"task_index": i, "task": tasks[i]} for i in sorted(tasks)]
    )


def _write_v30(out, table, episodes, tasks, per_episode) -> None:
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    _write_frames(out / V3_DATA_PATH.format(chunk_index=0, file_index=0), table, episodes)
    records = []
    for m, st in zip(episodes, per_episode, strict=True):
        rec: dict[str, Any] = {
            "episode_index": int(m["episode_index"]),
            "tasks": list(m["tasks"]),
            "length": int(m["length"]),
            "data/chunk_index": 0,
            "data/file_index": 0,
            "dataset_from_index": int(m["from"]),
            "dataset_to_index": int(m["to"]),
        }
        rec.update({k: v for k, v in m.items() if k.startswith("videos/")})
        for f, s in to_json(st).items():
            rec.update({f"stats/{f}/{k}": v for k, v in s.items()})
        rec.update({"meta/episodes/chunk_index": 0, "meta/episodes/file_index": 0})
        records.append(rec)
    path = out / V3_EPISODES_PATH.format(chunk_index=0, file_index=0)
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.Table.from_pylist(records), path)
    order = sorted(tasks)
    frame = pd.DataFrame(
        {"task_index": order}, index=pd.Index([tasks[i] for i in order], name="task")
    )
    frame.to_parquet(out / "meta" / "tasks.parquet")
