"""Write a selection of a local LeRobot dataset's episodes as a new dataset folder.

The new folder keeps every frame column of the source, renumbers the chosen episodes 0..k-1
(in source order) and the global ``index`` 0..N-1, and rebuilds the metadata for the
requested codebase version (:mod:`elicit_jax.data.lerobot_layout`), with statistics as
LeRobot computes them, quantiles included. Camera features keep the source's per-episode
statistics (LeRobot computes them from sampled frames; they cannot be recomputed from the
numbers alone); a source without them is refused. Videos are copied, never re-encoded: from
v3.0, each referenced ``file-XXX.mp4`` whole, with the episodes' timestamps unchanged; from
v2.x, each episode's file. A v3.0 video dataset cannot be written as v2.1 (that would need
cutting the shared video files).
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import atomic_path, dumps
from elicit_jax.data.lerobot import (
    load_frames,
    read_episodes,
    read_info,
    read_jsonl,
    read_tasks,
    select_rows,
    split_episodes,
)
from elicit_jax.data.lerobot_layout import (
    CURRENT_VERSION,
    EXPORT_VERSIONS,
    V2_VIDEO_PATH,
    V3_VIDEO_PATH,
    camera_keys,
    finish_info,
    version_notes,
    video_keys,
    write_folder,
)
from elicit_jax.data.lerobot_record import INFO_KEY, info_record
from elicit_jax.data.lerobot_stats import QUANTILE_KEYS, Stats, from_json
from elicit_jax.errors import ElicitError


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


def _camera_stats(
    source: Path, info: dict[str, Any], rows: list[dict[str, Any]], cameras: list[str]
) -> list[dict[str, Stats]]:
    """Each chosen episode's statistics of each camera feature, from the source metadata."""
    if not cameras:
        return [{} for _ in rows]
    if str(info["codebase_version"]).startswith("v3"):
        per_ep = {
            int(r["episode_index"]): {
                cam: {
                    k.removeprefix(f"stats/{cam}/"): v
                    for k, v in r.items()
                    if k.startswith(f"stats/{cam}/") and v is not None
                }
                for cam in cameras
            }
            for r in rows
        }
        where = "meta/episodes"
    else:
        path = source / "meta" / "episodes_stats.jsonl"
        listed = (
            {int(r["episode_index"]): r.get("stats", {}) for r in read_jsonl(path)}
            if path.is_file()
            else {}
        )
        per_ep = {
            e: {c: listed.get(e, {}).get(c, {}) for c in cameras}
            for e in (int(r["episode_index"]) for r in rows)
        }
        where = "meta/episodes_stats.jsonl"
    out = []
    for r in rows:
        e = int(r["episode_index"])
        for cam, st in per_ep[e].items():
            missing = [k for k in ("min", "max", "mean", "std", "count") if k not in st]
            if missing:
                raise ElicitError(
                    f"episode {e} has no {'/'.join(missing)} statistics for camera '{cam}' in "
                    f"{where}; LeRobot's training normalises cameras with them, so a new folder "
                    "cannot be written: export an episode list (-o selection.json) instead",
                    source,
                )
        out.append({cam: from_json({cam: st})[cam] for cam, st in per_ep[e].items()})
    return out


def _copy_videos(
    source: Path,
    info: dict[str, Any],
    new_info: dict[str, Any],
    rows: list[dict[str, Any]],
    meta: list[dict[str, Any]],
    tmp: Path,
) -> int:
    """Copy the chosen episodes' video files into ``tmp``; adds v3.0 locators to ``meta``."""
    keys = video_keys(info)
    if not keys:
        return 0
    src_v3 = str(info["codebase_version"]).startswith("v3")
    out_v3 = new_info["codebase_version"] == "v3.0"
    if src_v3 and not out_v3:
        raise ElicitError(
            "a v3.0 dataset with videos cannot be written as v2.1 (its episodes share video "
            "files that would need cutting); write v3.0, or export an episode list",
            source,
        )
    template = info.get("video_path") or (V3_VIDEO_PATH if src_v3 else V2_VIDEO_PATH)
    src_chunks = int(info.get("chunks_size") or 1000)
    chunks = int(new_info["chunks_size"])
    copies: dict[Path, Path] = {}
    for r, m in zip(rows, meta, strict=True):
        e, new = int(r["episode_index"]), int(m["episode_index"])
        for key in keys:
            if src_v3:
                loc = {f: r.get(f"videos/{key}/{f}") for f in ("chunk_index", "file_index")}
                if None in loc.values():
                    raise ElicitError(f"episode {e} has no video locator for '{key}'", source)
                rel = template.format(video_key=key, **loc)
                m.update({k: r[k] for k in r if k.startswith(f"videos/{key}/")})
            else:
                rel = template.format(video_key=key, episode_chunk=e // src_chunks, episode_index=e)
                if out_v3:
                    m.update(
                        {
                            f"videos/{key}/chunk_index": new // chunks,
                            f"videos/{key}/file_index": new % chunks,
                            f"videos/{key}/from_timestamp": 0.0,
                            f"videos/{key}/to_timestamp": m["length"] / float(info["fps"]),
                        }
                    )
                    dst = V3_VIDEO_PATH.format(
                        video_key=key, chunk_index=new // chunks, file_index=new % chunks
                    )
                else:
                    dst = V2_VIDEO_PATH.format(
                        video_key=key, episode_chunk=new // chunks, episode_index=new
                    )
            copies[source / rel] = tmp / (rel if src_v3 else dst)
    for src, dst in copies.items():
        if not src.is_file():
            raise ElicitError("missing video file", src)
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dst)
    return len(copies)


def export_lerobot(
    source: str | Path,
    out: str | Path,
    episodes: Sequence[int],
    *,
    version: str | None = None,
    header: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Write the chosen episodes of the dataset at ``source`` as a new folder ``out``.

    Args:
      source: a LeRobot dataset folder (v2.x or v3.0).
      out: the new folder (written atomically; replaced if it exists).
      episodes: source ``episode_index`` values to keep.
      version: codebase version of the new folder, ``v3.0`` (the default, whatever the
        source's) or ``v2.1``; the returned notes say what either means for LeRobot.
      header: elicit-jax artifact header, stored as ``artifact.json`` at the folder's root;
        its export record (``episodes``...), if any, is also kept in ``meta/info.json``.

    Returns:
      ``version`` written, ``source_episodes`` (in order; new index = position),
      ``cameras`` (features whose statistics were carried over), ``videos`` (files copied)
      and ``notes``.
    """
    source, out = Path(source), Path(out)
    if out.resolve() == source.resolve():
        raise ElicitError("output must differ from the source dataset folder", out)
    info = read_info(source)
    version = version or CURRENT_VERSION
    if version not in EXPORT_VERSIONS:
        raise ElicitError(f"cannot write LeRobot codebase version {version!r} ({EXPORT_VERSIONS})")
    tasks = read_tasks(source, info)
    rows = select_rows(source, read_episodes(source, info), episodes)
    cameras = camera_keys(info)
    cam_stats = _camera_stats(source, info, rows, cameras)
    table, meta = _gather(source, info, episodes)
    new_info = finish_info(info, version, len(meta), table.num_rows, len(tasks))
    if header is not None and "episodes" in header:
        new_info[INFO_KEY] = info_record(header)
    with atomic_path(out) as tmp:
        tmp.mkdir()
        n_videos = _copy_videos(source, info, new_info, rows, meta, tmp)
        write_folder(tmp, table, meta, tasks, new_info, cam_stats)
        if header is not None:
            (tmp / "artifact.json").write_text(dumps(header) + "\n")
    bare = sorted({c for st in cam_stats for c, s in st.items() if QUANTILE_KEYS[0] not in s})
    notes = version_notes(info["codebase_version"], version, out) + (
        [
            f"the source's statistics of {', '.join(bare)} have no quantiles (the LeRobot that "
            "recorded it computed none, and they cannot be recomputed without decoding frames): "
            "normalise cameras by MEAN_STD, LeRobot's default for images"
        ]
        if bare
        else []
    )
    return {
        "version": version,
        "source_episodes": [m["source_episode_index"] for m in meta],
        "cameras": cameras,
        "videos": n_videos,
        "notes": notes,
    }
