"""Write any demonstrations as a new LeRobot dataset (v3.0 by default, or v2.1).

Frames: ``observation.state`` (the demos' obs; its ``names`` spell out the obs fields, e.g.
``robot0_eef_pos.0``), ``action``, ``next.reward``, ``next.done`` (true on each episode's last
frame), ``next.success`` (true on the last frame of a successful episode — what LeRobot's
simulation datasets record and elicit-jax's import reads back), numeric extra columns as
features of their own, and LeRobot's bookkeeping columns (``timestamp`` = frame / fps,
``frame_index``, ``episode_index``, ``index``, ``task_index``). Vectors are fixed-size
float32 lists, as LeRobot's own writer stores them.

Each step's task text (the demos' ``task`` column, from a multi-task LeRobot import; else
their one task) becomes its ``task_index``, each episode's metadata lists its own tasks.
LeRobot has no place for operators, observation-field slices, declared action bounds,
robomimic ``env_args``, the demos' names in their source dataset or elicit-jax's own
columns (``pre_filter_*``, ``part``, ``subset``: not features, so LeRobot's ``add_frame``
after ``resume()`` does not ask for them): they go to the folder's record
(:mod:`elicit_jax.data.lerobot_record`: ``artifact.json`` and a copy in ``meta/info.json``),
from which ``elicit-jax import`` restores them. Everything not written is listed in the notes.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import atomic_path, dumps
from elicit_jax.data.demos import SOURCE_EPISODE, TASK_COLUMN, Demos
from elicit_jax.data.lerobot_layout import (
    CURRENT_VERSION,
    EXPORT_VERSIONS,
    finish_info,
    version_notes,
    write_folder,
)
from elicit_jax.data.lerobot_record import (
    INFO_KEY,
    OBS_FEATURE,
    OWN_COLUMNS,
    export_record,
    info_record,
)
from elicit_jax.errors import ElicitError

BOOKKEEPING = ("timestamp", "frame_index", "episode_index", "index", "task_index")


def _feature(dtype: str, width: int | None, names: list[str] | None = None) -> dict[str, Any]:
    return {"dtype": dtype, "shape": [1 if width is None else width], "names": names}


def obs_names(demos: Demos) -> list[str] | None:
    """Per-dimension names of the observation, from its fields (``None`` without fields)."""
    fields = sorted(demos.obs_fields, key=lambda f: f.start)
    names = [f.name if f.size == 1 else f"{f.name}.{i}" for f in fields for i in range(f.size)]
    return names if len(names) == demos.obs_dim else None


def frames(demos: Demos, fps: int) -> tuple[Any, list[dict[str, Any]], dict[str, Any], list[str]]:
    """The demos as LeRobot frames.

    Returns:
      ``(table, episodes, features, skipped)``: the Arrow frame table (episodes renumbered
      0..E-1 in row order), per-episode metadata rows, the ``features`` of ``info.json`` and
      the extra columns that have no LeRobot form (strings).
    """
    import pyarrow as pa

    bounds = demos.episode_bounds()
    n = demos.n_steps
    lengths = np.array([e - s for _, s, e in bounds])
    starts = np.array([s for _, s, _ in bounds])
    new_ep = np.repeat(np.arange(len(bounds)), lengths)
    frame = np.arange(n) - np.repeat(starts, lengths)
    last = np.zeros(n, bool)
    last[np.cumsum(lengths) - 1] = True

    def fixed(arr: np.ndarray) -> Any:
        arr = np.ascontiguousarray(arr)
        return pa.FixedSizeListArray.from_arrays(pa.array(arr.reshape(-1)), arr.shape[1])

    cols: dict[str, Any] = {
        OBS_FEATURE: fixed(demos.obs.astype(np.float32)),
        "action": fixed(demos.action.astype(np.float32)),
        "next.reward": pa.array(demos.reward.astype(np.float32)),
        "next.done": pa.array(last),
        "next.success": pa.array(last & demos.success.astype(bool)),
    }
    features = {
        OBS_FEATURE: _feature("float32", demos.obs_dim, obs_names(demos)),
        "action": _feature("float32", demos.action_dim),
        "next.reward": _feature("float32", None),
        "next.done": _feature("bool", None),
        "next.success": _feature("bool", None),
    }
    skipped = []
    for k, v in sorted(demos.extra.items()):
        v = np.asarray(v)
        if k in (TASK_COLUMN, SOURCE_EPISODE, *OWN_COLUMNS):
            continue  # written as task_index (below); names and own columns: in the record
        if v.dtype.kind not in "biuf" or k in cols or k in BOOKKEEPING:
            skipped.append(k)
            continue
        cols[k] = fixed(v) if v.ndim == 2 else pa.array(v)
        features[k] = _feature(v.dtype.name, v.shape[1] if v.ndim == 2 else None)
    cols.update(
        timestamp=pa.array((frame / fps).astype(np.float32)),
        frame_index=pa.array(frame.astype(np.int64)),
        episode_index=pa.array(new_ep.astype(np.int64)),
        index=pa.array(np.arange(n, dtype=np.int64)),
    )
    features.update(
        {k: _feature("float32" if k == "timestamp" else "int64", None) for k in BOOKKEEPING}
    )
    task_of, tasks = frame_task_index(demos)
    cols["task_index"] = pa.array(task_of)
    episodes = [
        {
            "episode_index": i,
            "tasks": [tasks[t] for t in dict.fromkeys(task_of[s:e].tolist())],
            "length": e - s,
            "from": s,
            "to": e,
        }
        for i, (_, s, e) in enumerate(bounds)
    ]
    return pa.table(cols), episodes, features, skipped


def frame_task_index(demos: Demos) -> tuple[np.ndarray, dict[int, str]]:
    """Each step's ``task_index`` and the task texts (index -> text, in order of first use):
    the demos' per-step ``task`` column when they have one (a multi-task LeRobot import),
    else their one task."""
    texts = demos.extra.get(TASK_COLUMN)
    if texts is None:
        return np.zeros(demos.n_steps, np.int64), {0: demos.task}
    texts = np.asarray([str(t) for t in texts], dtype=object)
    order = list(dict.fromkeys(texts.tolist()))
    lookup = {t: i for i, t in enumerate(order)}
    return np.array([lookup[t] for t in texts], np.int64), dict(enumerate(order))


def write_fresh(
    demos: Demos,
    out: str | Path,
    *,
    fps: int,
    version: str = CURRENT_VERSION,
    header: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Write ``demos`` as a new LeRobot dataset folder ``out`` (atomically).

    Args:
      demos: the demonstrations.
      out: the new folder.
      fps: frame rate (LeRobot needs an integer).
      version: ``v3.0`` (LeRobot 0.4 and later) or ``v2.1`` (LeRobot 0.1-0.3).
      header: elicit-jax provenance; stored with the export record (operators, obs fields,
        action bounds) as ``artifact.json``.

    Returns:
      ``version``, ``features`` written and ``notes`` (what has no LeRobot form).
    """
    if version not in EXPORT_VERSIONS:
        raise ElicitError(f"cannot write LeRobot codebase version {version!r} ({EXPORT_VERSIONS})")
    if int(fps) != fps or fps <= 0:
        raise ElicitError(f"LeRobot needs a positive integer frame rate, not {fps}")
    table, episodes, features, skipped = frames(demos, int(fps))
    tasks = frame_task_index(demos)[1]
    base = {"codebase_version": version, "robot_type": None, "fps": int(fps), "features": features}
    info = finish_info(base, version, len(episodes), table.num_rows, len(tasks))
    fields = ", ".join(f"{f.name} [{f.start}:{f.stop}]" for f in demos.obs_fields)
    notes = [
        f"{OBS_FEATURE} holds the demos' observation" + (f" ({fields})" if fields else ""),
        "operators, obs fields, action bounds, env_args, source demo names and elicit-jax's own "
        "columns have no place in LeRobot's format: kept in artifact.json and under "
        f"'{INFO_KEY}' in meta/info.json (which LeRobot's v2.1 -> v3.0 converter carries), "
        "from which elicit-jax import restores them, matching episodes by content",
    ]
    if skipped:
        notes.append(f"non-numeric columns not written: {', '.join(skipped)}")
    notes += version_notes(CURRENT_VERSION, version, out)
    record = {**dict(header or {}), **export_record(demos), "notes": notes}
    info[INFO_KEY] = info_record(record)
    with atomic_path(out) as tmp:
        tmp.mkdir()
        write_folder(tmp, table, episodes, tasks, info)
        (tmp / "artifact.json").write_text(dumps(record) + "\n")
    return {"version": version, "features": list(features), "notes": notes}
