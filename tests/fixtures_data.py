"""Builders of small datasets in the real on-disk layouts (robomimic HDF5, LeRobot v2.1/v3.0).

Written independently of elicit_jax's own exporters, following the layouts the libraries
write today, so that tests check our readers and writers against the formats rather than
against ourselves:

* robomimic 0.3 (as robosuite's conversion writes it): ``data/demo_i/{actions, rewards,
  dones, states, obs/<key>, next_obs/<key>}`` with ``num_samples`` and ``model_file``;
  ``data.attrs`` ``env_args`` and ``total``; ``mask/<key>`` byte strings.
* LeRobot v3.0 as LeRobot 0.6.x records it: vectors as fixed-size float32 lists, one row
  group per episode, per-episode ``stats/<feature>/<key>`` columns and ``meta/stats.json``
  aggregated episode by episode (with the quantiles q01..q99 of LeRobot's histogram
  estimator, :func:`lerobot_reference_stats`), optionally a video camera with its files,
  locators and per-episode statistics.
* LeRobot v2.1 as LeRobot 0.3.x records it: one Parquet per episode,
  ``episodes_stats.jsonl`` (min/max/mean/std/count: 0.3.x computes no quantiles).
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import sys
from pathlib import Path

import numpy as np


def toy_episode(rng: np.random.Generator, t: int, obs_dim: int = 4, act_dim: int = 2) -> dict:
    """Random episode: obs (t, obs_dim), action (t, act_dim) in [-0.9, 0.9], sparse reward."""
    reward = np.zeros(t, np.float32)
    reward[-1] = 1.0
    return {
        "obs": rng.normal(size=(t, obs_dim)).astype(np.float32),
        "action": rng.uniform(-0.9, 0.9, size=(t, act_dim)).astype(np.float32),
        "reward": reward,
    }


def write_robomimic(
    path: Path,
    demos: dict[str, dict[str, np.ndarray]],
    masks: dict[str, list[str]] | None = None,
    env_name: str = "NutAssemblySquare",
) -> Path:
    """robomimic layout: ``data/<name>/{actions, rewards, dones, obs/<key>}``, ``mask/<key>``.

    ``demos[name]`` holds ``actions``, optional ``rewards``, and ``obs/<key>`` entries.
    """
    import h5py

    env_args = {"env_name": env_name, "type": 1, "env_kwargs": {"reward_shaping": False}}
    with h5py.File(path, "w") as f:
        data = f.create_group("data")
        data.attrs["env_args"] = json.dumps(env_args)
        total = 0
        for name, d in demos.items():
            g = data.create_group(name)
            g.create_dataset("actions", data=d["actions"])
            t = len(d["actions"])
            g.create_dataset("states", data=np.arange(t * 5, dtype=np.float64).reshape(t, 5))
            g.attrs["model_file"] = "<mujoco model='fixture'/>"
            if "rewards" in d:
                g.create_dataset("rewards", data=d["rewards"])
            dones = np.zeros(t, np.int64)
            if t:
                dones[-1] = 1
            g.create_dataset("dones", data=dones)
            for key, arr in d.items():
                if key.startswith("obs/"):
                    g.create_dataset(key, data=arr)
                    nxt = np.concatenate([arr[1:], arr[-1:]]) if t else arr
                    g.create_dataset("next_" + key, data=nxt)
            g.attrs["num_samples"] = t
            total += t
        data.attrs["total"] = total
        for key, names in (masks or {}).items():
            f.create_dataset(f"mask/{key}", data=np.array(names, dtype="S"))
    return path


def robomimic_demo(rng: np.random.Generator, t: int, success: bool = True) -> dict:
    """A demo with the standard low-dim keys: eef pos 3, eef quat 4, gripper 2, object 14."""
    rewards = np.zeros(t)
    if success:
        rewards[-1] = 1.0
    return {
        "actions": rng.uniform(-1, 1, size=(t, 7)),
        "rewards": rewards,
        "obs/robot0_eef_pos": rng.normal(size=(t, 3)),
        "obs/robot0_eef_quat": rng.normal(size=(t, 4)),
        "obs/robot0_gripper_qpos": rng.normal(size=(t, 2)),
        "obs/object": rng.normal(size=(t, 14)),
        "obs/agentview_image": np.zeros((t, 2, 2, 3), np.uint8),
    }


QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
CAMERA = "observation.images.top"


def lerobot_reference_stats(values: np.ndarray, quantiles: bool = True) -> dict:
    """One feature's statistics over one episode as LeRobot (0.4+) records them.

    Population std from the mean of squares, in the data's dtype promoted to at least
    float32; quantiles from a 5000-bin histogram over [min - 1e-10, max + 1e-10], read at the
    first bin whose cumulative count reaches q * n and interpolated inside it.
    """
    x = np.asarray(values)
    x = x.reshape(len(x), -1)
    x = x.astype(np.result_type(x.dtype, np.float32))
    mean = x.mean(axis=0)
    out = {
        "min": x.min(axis=0),
        "max": x.max(axis=0),
        "mean": mean,
        "std": np.sqrt(np.maximum(0, (x * x).mean(axis=0) - mean * mean)),
        "count": np.array([len(x)]),
    }
    if not quantiles:
        return out
    for q in QUANTILES:
        row = []
        for d in range(x.shape[1]):
            if len(x) < 2:
                row.append(float(mean[d]))
                continue
            col = x[:, d]
            edges = np.linspace(col.min() - 1e-10, col.max() + 1e-10, 5001)
            cum = np.cumsum(np.histogram(col, bins=edges)[0]).astype(float)
            target = q * len(col)
            reached = np.flatnonzero(cum >= target)
            i = int(reached[0]) if len(reached) else len(cum)
            if i == 0:
                row.append(edges[0])
            elif i == len(cum):
                row.append(edges[-1])
            elif cum[i] == cum[i - 1]:
                row.append(edges[i])
            else:
                frac = (target - cum[i - 1]) / (cum[i] - cum[i - 1])
                row.append(edges[i] + frac * (edges[i + 1] - edges[i]))
        out[f"q{int(q * 100):02d}"] = np.array(row)
    return out


def lerobot_running_aggregate(total: dict | None, ep: dict) -> dict:
    """The recorder's update of dataset statistics with one more episode's."""
    if total is None:
        return {k: np.asarray(v) for k, v in ep.items()}
    n1, n2 = total["count"], ep["count"]
    n = n1 + n2
    mean = (total["mean"] * n1 + ep["mean"] * n2) / n
    var = (
        (total["std"] ** 2 + (total["mean"] - mean) ** 2) * n1
        + (ep["std"] ** 2 + (ep["mean"] - mean) ** 2) * n2
    ) / n
    out = {
        "min": np.minimum(total["min"], ep["min"]),
        "max": np.maximum(total["max"], ep["max"]),
        "mean": mean,
        "std": np.sqrt(var),
        "count": n,
    }
    for k in total:
        if k.startswith("q") and k in ep:
            out[k] = (total[k] * n1 + ep[k] * n2) / n
    return out


def _camera_stats(rng: np.random.Generator, t: int, quantiles: bool) -> dict:
    """Per-channel stats (3, 1, 1) in [0, 1], as LeRobot computes from sampled frames."""
    lo = rng.uniform(0, 0.2, size=(3, 1, 1))
    hi = rng.uniform(0.8, 1.0, size=(3, 1, 1))
    mean = (lo + hi) / 2
    out = {"min": lo, "max": hi, "mean": mean, "std": (hi - lo) / 4, "count": np.array([t])}
    if quantiles:
        for q in QUANTILES:
            out[f"q{int(q * 100):02d}"] = lo + q * (hi - lo)
    return out


def _frames_table(episodes: list[dict], start_index: int = 0, fixed: bool = True):
    """LeRobot frame rows as HF ``datasets`` writes them: vectors as fixed-size float32 lists
    (``fixed=False``: variable lists, as some older datasets hold them)."""
    import pyarrow as pa

    cols: dict[str, list] = {
        k: []
        for k in (
            "observation.state",
            "action",
            "next.reward",
            "next.done",
            "next.success",
            "timestamp",
            "frame_index",
            "episode_index",
            "index",
            "task_index",
        )
    }
    index = start_index
    for ep in episodes:
        t = len(ep["state"])
        cols["observation.state"] += ep["state"].astype(np.float32).tolist()
        cols["action"] += ep["action"].astype(np.float32).tolist()
        cols["timestamp"] += (np.arange(t) / 10).astype(np.float32).tolist()
        cols["frame_index"] += list(range(t))
        cols["episode_index"] += [ep["episode_index"]] * t
        cols["index"] += list(range(index, index + t))
        cols["task_index"] += [ep.get("task_index", 0)] * t
        cols["next.reward"] += ep["reward"].astype(np.float32).tolist()
        cols["next.done"] += [False] * (t - 1) + [True]
        cols["next.success"] += ep["success_flags"].tolist()
        index += t
    vec = pa.list_(pa.float32(), 6) if fixed else pa.list_(pa.float32())
    types = {
        "observation.state": vec,
        "action": vec,
        "timestamp": pa.float32(),
        "next.reward": pa.float32(),
        "next.done": pa.bool_(),
        "next.success": pa.bool_(),
    }
    return pa.table({k: pa.array(v, types.get(k, pa.int64())) for k, v in cols.items()})


def _write_by_episode(path: Path, table) -> None:
    """One row group per episode, as LeRobot's recorder appends them."""
    import pyarrow.parquet as pq

    ep = table.column("episode_index").to_numpy()
    starts = np.concatenate([[0], np.flatnonzero(np.diff(ep)) + 1, [len(ep)]])
    path.parent.mkdir(parents=True, exist_ok=True)
    with pq.ParquetWriter(path, table.schema, compression="snappy") as w:
        for a, b in itertools.pairwise(starts):
            w.write_table(table.slice(int(a), int(b - a)))


def lerobot_episode(rng: np.random.Generator, index: int, t: int, success: bool = True) -> dict:
    """Episode with state (t, 6), action (t, 6) in degrees-like units, next.* columns."""
    flags = np.zeros(t, bool)
    if success:
        flags[-1] = True
    return {
        "episode_index": index,
        "state": rng.normal(size=(t, 6)),
        "action": rng.uniform(-90, 90, size=(t, 6)),
        "reward": flags.astype(np.float32),
        "success_flags": flags,
        "task_index": 0,
    }


def _features(camera: bool = False) -> dict:
    def f(dtype: str, shape: list[int], names=None) -> dict:
        return {"dtype": dtype, "shape": shape, "names": names}

    feats = {
        "observation.state": f("float32", [6], [f"joint_{i}.pos" for i in range(6)]),
        "action": f("float32", [6], [f"joint_{i}.pos" for i in range(6)]),
        "next.reward": f("float32", [1]),
        "next.done": f("bool", [1]),
        "next.success": f("bool", [1]),
    }
    if camera:
        feats[CAMERA] = {
            "dtype": "video",
            "shape": [8, 8, 3],
            "names": ["height", "width", "channels"],
            "info": {
                "video.height": 8,
                "video.width": 8,
                "video.codec": "av1",
                "video.pix_fmt": "yuv420p",
                "video.is_depth_map": False,
                "video.fps": 10,
                "video.channels": 3,
                "has_audio": False,
            },
        }
    feats.update(
        {
            "timestamp": f("float32", [1]),
            "frame_index": f("int64", [1]),
            "episode_index": f("int64", [1]),
            "index": f("int64", [1]),
            "task_index": f("int64", [1]),
        }
    )
    return feats


def _numeric_stats(table, quantiles: bool) -> dict:
    """Stats of every numeric frame column of one episode's rows."""
    import pyarrow as pa

    out = {}
    for name in table.column_names:
        col = table.column(name).combine_chunks()
        if pa.types.is_fixed_size_list(col.type) or pa.types.is_list(col.type):
            values = col.flatten().to_numpy().reshape(len(col), -1)
        else:
            values = col.to_numpy(zero_copy_only=False)
        out[name] = lerobot_reference_stats(values, quantiles)
    return out


def _json(stats: dict) -> dict:
    return {f: {k: np.asarray(v).tolist() for k, v in s.items()} for f, s in stats.items()}


def write_lerobot_v21(
    root: Path, episodes: list[dict], tasks: list[str], chunks_size=1000, camera: bool = False
):
    """LeRobot codebase v2.1 folder: one Parquet per episode + jsonl metadata (+ a camera)."""
    root.mkdir(parents=True)
    n_frames = sum(len(e["state"]) for e in episodes)
    info = {
        "codebase_version": "v2.1",
        "robot_type": "so100",
        "total_episodes": len(episodes),
        "total_frames": n_frames,
        "total_tasks": len(tasks),
        "total_videos": len(episodes) if camera else 0,
        "total_chunks": 1,
        "chunks_size": chunks_size,
        "fps": 10,
        "splits": {"train": f"0:{len(episodes)}"},
        "data_path": "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet",
        "video_path": (
            "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"
            if camera
            else None
        ),
        "features": _features(camera),
    }
    (root / "meta").mkdir()
    (root / "meta" / "info.json").write_text(json.dumps(info, indent=4))
    rng = np.random.default_rng(1)
    index, lines, stat_lines = 0, [], []
    for ep in episodes:
        e = ep["episode_index"]
        path = root / "data" / f"chunk-{e // chunks_size:03d}" / f"episode_{e:06d}.parquet"
        table = _frames_table([ep], index)
        _write_by_episode(path, table)
        index += len(ep["state"])
        task = tasks[ep.get("task_index", 0)]
        lines.append({"episode_index": e, "tasks": [task], "length": len(ep["state"])})
        stats = _numeric_stats(table, quantiles=False)
        if camera:
            stats[CAMERA] = _camera_stats(rng, len(ep["state"]), quantiles=False)
            video = root / "videos" / f"chunk-{e // chunks_size:03d}" / CAMERA
            video.mkdir(parents=True, exist_ok=True)
            (video / f"episode_{e:06d}.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42 ep%d" % e)
        stat_lines.append({"episode_index": e, "stats": _json(stats)})
    (root / "meta" / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in lines))
    (root / "meta" / "episodes_stats.jsonl").write_text(
        "".join(json.dumps(r) + "\n" for r in stat_lines)
    )
    (root / "meta" / "tasks.jsonl").write_text(
        "".join(json.dumps({"task_index": i, "task": t}) + "\n" for i, t in enumerate(tasks))
    )
    return root


def write_lerobot_v30(
    root: Path,
    episodes: list[dict],
    tasks: list[str],
    per_file: int = 2,
    camera: bool = False,
    fixed: bool = True,
):
    """LeRobot codebase v3.0 folder as LeRobot 0.6.x records it: several episodes per data
    (and video) file, Parquet metadata with per-episode stats, ``meta/stats.json``."""
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    root.mkdir(parents=True)
    info = {
        "codebase_version": "v3.0",
        "robot_type": "so100",
        "total_episodes": len(episodes),
        "total_frames": sum(len(e["state"]) for e in episodes),
        "total_tasks": len(tasks),
        "chunks_size": 1000,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "fps": 10,
        "splits": {"train": f"0:{len(episodes)}"},
        "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
        "video_path": (
            "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
            if camera
            else None
        ),
        "features": _features(camera),
    }
    (root / "meta" / "episodes" / "chunk-000").mkdir(parents=True)
    (root / "meta" / "info.json").write_text(json.dumps(info, indent=4))
    rng = np.random.default_rng(1)
    records, index, total = [], 0, {}
    for file_index in range(0, len(episodes), per_file):
        group = episodes[file_index : file_index + per_file]
        table = _frames_table(group, index, fixed=fixed)
        _write_by_episode(
            root / "data" / "chunk-000" / f"file-{file_index // per_file:03d}.parquet", table
        )
        if camera:
            video = root / "videos" / CAMERA / "chunk-000"
            video.mkdir(parents=True, exist_ok=True)
            (video / f"file-{file_index // per_file:03d}.mp4").write_bytes(
                b"\x00\x00\x00\x18ftypmp42 file%d" % (file_index // per_file)
            )
        offset, t_video = 0, 0.0
        for ep in group:
            t = len(ep["state"])
            stats = _numeric_stats(table.slice(offset, t), quantiles=True)
            if camera:
                stats[CAMERA] = _camera_stats(rng, t, quantiles=True)
            rec = {
                "episode_index": ep["episode_index"],
                "tasks": [tasks[ep.get("task_index", 0)]],
                "length": t,
                "data/chunk_index": 0,
                "data/file_index": file_index // per_file,
                "dataset_from_index": index,
                "dataset_to_index": index + t,
            }
            if camera:
                rec.update(
                    {
                        f"videos/{CAMERA}/chunk_index": 0,
                        f"videos/{CAMERA}/file_index": file_index // per_file,
                        f"videos/{CAMERA}/from_timestamp": t_video,
                        f"videos/{CAMERA}/to_timestamp": t_video + t / 10,
                    }
                )
            for f, st in _json(stats).items():
                rec.update({f"stats/{f}/{k}": v for k, v in st.items()})
            rec.update({"meta/episodes/chunk_index": 0, "meta/episodes/file_index": 0})
            records.append(rec)
            for f, st in stats.items():
                total[f] = lerobot_running_aggregate(total.get(f), st)
            index, offset, t_video = index + t, offset + t, t_video + t / 10
    pq.write_table(
        pa.Table.from_pylist(records), root / "meta" / "episodes" / "chunk-000" / "file-000.parquet"
    )
    df = pd.DataFrame({"task_index": list(range(len(tasks)))}, index=pd.Index(tasks, name="task"))
    df.to_parquet(root / "meta" / "tasks.parquet")
    (root / "meta" / "stats.json").write_text(json.dumps(_json(total), indent=4))
    return root


# the keys LeRobot 0.6.x's DatasetInfo knows; it drops any other key of meta/info.json when
# it rewrites the file (resume(), save_episode())
LEROBOT_INFO_KEYS = (
    "codebase_version", "fps", "features", "total_episodes", "total_frames", "total_tasks",
    "chunks_size", "data_files_size_in_mb", "video_files_size_in_mb", "data_path", "video_path",
    "robot_type", "splits", "tools",
)  # fmt: skip


def append_lerobot_v30(root: Path, episodes: list[dict], task: str) -> Path:
    """Append episodes to a v3.0 folder as LeRobot 0.6.x's ``resume()`` + ``save_episode()``
    do: the new frames and their metadata rows go to the next data / episodes-metadata file
    (resuming never writes into the existing ones), ``episode_index`` and ``index`` continue,
    a task not yet known is appended to ``meta/tasks.parquet``, and ``meta/info.json`` is
    rewritten with its counters updated and only the keys LeRobot knows."""
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    info = json.loads((root / "meta" / "info.json").read_text())
    tasks = pd.read_parquet(root / "meta" / "tasks.parquet")
    if task not in tasks.index:
        tasks.loc[task] = len(tasks)
        tasks.to_parquet(root / "meta" / "tasks.parquet")
    old_meta = sorted((root / "meta" / "episodes").glob("chunk-*/file-*.parquet"))
    last = pq.read_table(old_meta[-1]).to_pylist()[-1]
    file_index = int(last["meta/episodes/file_index"]) + 1
    start = int(last["dataset_to_index"])
    for ep in episodes:
        ep["task_index"] = int(tasks.loc[task, "task_index"])
    table = _frames_table(episodes, start)
    _write_by_episode(root / "data" / "chunk-000" / f"file-{file_index:03d}.parquet", table)
    records, offset = [], 0
    for ep in episodes:
        t = len(ep["state"])
        rec = {
            "episode_index": ep["episode_index"],
            "tasks": [task],
            "length": t,
            "data/chunk_index": 0,
            "data/file_index": file_index,
            "dataset_from_index": start + offset,
            "dataset_to_index": start + offset + t,
        }
        for f, st in _json(_numeric_stats(table.slice(offset, t), quantiles=True)).items():
            rec.update({f"stats/{f}/{k}": v for k, v in st.items()})
        rec.update({"meta/episodes/chunk_index": 0, "meta/episodes/file_index": file_index})
        records.append(rec)
        offset += t
    pq.write_table(
        pa.Table.from_pylist(records),
        root / "meta" / "episodes" / "chunk-000" / f"file-{file_index:03d}.parquet",
    )
    info.update(
        total_episodes=info["total_episodes"] + len(episodes),
        total_frames=info["total_frames"] + table.num_rows,
        total_tasks=len(tasks),
    )
    info["splits"] = {"train": f"0:{info['total_episodes']}"}
    info = {k: v for k, v in info.items() if k in LEROBOT_INFO_KEYS}
    (root / "meta" / "info.json").write_text(json.dumps(info, indent=4))
    return root


def own_robomimic_file(path: Path, n_base: int = 12, n_alt: int = 6, t: int = 40) -> Path:
    """A robomimic file shaped like a real teleoperated one, to walk the whole tool through.

    7-D actions: 3 translation dims (the operator's style), 2 dims always 0, a small rotation
    and a ±1 gripper; non-default obs keys ``eef_pos`` (3), ``gripper_qpos`` (2) and
    ``object_pose`` (7); two operator mask keys, ``op_base`` (demo_0..) and ``op_alt``. The
    base operator heads straight for the object; ``op_alt`` starts from the same states but
    heads 90° off in the xy-plane, so its actions conflict with the base's in familiar states.
    """
    rng = np.random.default_rng(0)
    demos, names = {}, {"op_base": [], "op_alt": []}
    for i in range(n_base + n_alt):
        alt = i >= n_base
        obj = rng.normal(0.0, 0.02, 3)
        eef = rng.uniform(-0.5, 0.5, 3)
        pos, act = [], []
        for _ in range(t):
            step = np.clip(obj - eef, -0.3, 0.3)
            if alt:
                step = np.array([-step[1], step[0], step[2]])
            grip = 1.0 if np.linalg.norm(obj - eef) > 0.15 else -1.0
            pos.append(eef.copy())
            act.append([*step, 0.0, 0.0, rng.normal(0.0, 0.02), grip])
            eef = eef + 0.1 * step
        act = np.asarray(act)
        pose = np.concatenate([np.tile(obj, (t, 1)), np.tile([1.0, 0, 0, 0], (t, 1))], axis=1)
        demos[f"demo_{i}"] = {
            "actions": act,
            "rewards": np.r_[np.zeros(t - 1), 1.0],
            "obs/eef_pos": np.asarray(pos),
            "obs/gripper_qpos": np.stack([act[:, 6], -act[:, 6]], axis=1) * 0.04,
            "obs/object_pose": pose,
        }
        names["op_alt" if alt else "op_base"].append(f"demo_{i}")
    return write_robomimic(path, demos, masks=names, env_name="NutAssemblySquare")


def skip_without_robosuite() -> None:
    """Skip the calling test module when the robosuite extra is not installed, except under
    ELICIT_JAX_REQUIRE_ROBOSUITE=1 (CI), where its tests run and fail instead."""
    import os

    import pytest

    try:
        import robosuite  # noqa: F401
    except ModuleNotFoundError:
        if os.environ.get("ELICIT_JAX_REQUIRE_ROBOSUITE") != "1":
            pytest.skip("robosuite extra not installed", allow_module_level=True)


def invoke(*args):
    """``elicit-jax ARGS`` through Typer's ``CliRunner`` (arguments as strings): its Result."""
    from typer.testing import CliRunner

    from elicit_jax.cli import app

    return CliRunner().invoke(app, [str(a) for a in args])


def cli_ok(*args):
    """:func:`invoke` that must exit 0; fails with the output and exception otherwise."""
    result = invoke(*args)
    assert result.exit_code == 0, (result.output, result.exception)
    return result


def run_cli(monkeypatch, capsys, *args) -> tuple[int, str, str]:
    """Run ``elicit-jax ARGS`` in-process through ``main``; returns (exit code, out, err)."""
    from elicit_jax.cli import main

    monkeypatch.setattr(sys, "argv", ["elicit-jax", *map(str, args)])
    monkeypatch.setenv("COLUMNS", "250")  # rich wraps tables at the terminal width
    code = 0
    try:
        main()
    except SystemExit as e:
        code = e.code or 0
    out, err = capsys.readouterr()
    return code, out, err


def tiny_episodes(n: int = 6, t: int = 20, seed: int = 0) -> list[dict]:
    """``n`` random episodes of ``t`` steps: obs (t, 3), action (t, 2) in [-1, 1]."""
    rng = np.random.default_rng(seed)
    return [
        {"obs": rng.normal(size=(t, 3)), "action": rng.uniform(-1, 1, size=(t, 2))}
        for _ in range(n)
    ]


def tiny_train_config(**overrides):
    """A training config that trains in a second: 2 members of one 8-unit layer, 2 epochs."""
    from elicit_jax.policy.config import TrainConfig

    base = {
        "ensemble_size": 2,
        "hidden": (8,),
        "epochs": 2,
        "batch_size": 32,
        "checkpoint_every": 2,
        "progress_every": 1,
        "seeds": (0,),
    }
    return TrainConfig(**{**base, **overrides})


def tiny_run(d: Path, **overrides) -> Path:
    """``d/demos.parquet`` (tiny episodes) and a tiny training run on them in ``d/run``."""
    from elicit_jax.data.demos import from_episodes, write_demos
    from elicit_jax.policy.train import train_policy

    demos = from_episodes(tiny_episodes(), operators="base")
    write_demos(d / "demos.parquet", demos)
    train_policy(demos, tiny_train_config(**overrides), d / "run", quiet=True)
    return d


@dataclasses.dataclass(frozen=True)
class SessionInputs:
    """What an elicitation session needs: D_base, the base policy and the fitted (λ, η)."""

    base: Path
    policy: Path
    lam: float
    eta: float

    def session_config(self, operator: str, **overrides):
        """A square-nut ``SessionConfig`` on these inputs for ``operator``: 1 practice, 2
        prompt and 2 demonstration episodes, at most 4 episodes; ``overrides`` replace fields."""
        from elicit_jax.compat.thresholds import Thresholds
        from elicit_jax.elicit.config import SessionConfig

        base = dict(
            task="square-nut",
            policy=str(self.policy),
            base_demos=str(self.base),
            thresholds=Thresholds(self.lam, self.eta, "given"),
            operator=operator,
            demos=2,
            practice=1,
            prompt=2,
            max_episodes=4,
        )
        return SessionConfig(**{**base, **overrides})


def square_nut_session_inputs(d: Path) -> SessionInputs:
    """The square-nut session tests' inputs in ``d``: D_base (10 base demos), a tiny base
    policy (3 × 64-64, 40 epochs) and (λ, η) fitted, with the library's ``fit_thresholds``,
    on 3 same-style and 3 conflict-flip-pause demos from other initial states (which the fit
    must separate perfectly)."""
    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.compat.score import score_demos
    from elicit_jax.compat.threshold_fit import fit_thresholds
    from elicit_jax.data.demos import concat_demos, from_episodes, read_demos
    from elicit_jax.policy.config import TrainConfig
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.policy.train import train_policy
    from elicit_jax.sim.collect import CollectConfig, collect, collect_episodes
    from elicit_jax.sim.env import make_task

    collect(
        CollectConfig(task="square-nut", operator="base", episodes=10, seed=0), d / "base.parquet"
    )
    cfg = TrainConfig.from_profile(
        "cpu", hidden=(64, 64), ensemble_size=3, epochs=40, checkpoint_every=20, progress_every=20
    )
    train_policy(read_demos(d / "base.parquet"), cfg, d / "base_run", quiet=True)
    task = make_task("square-nut")
    parts = []
    for op in ("same-style", "conflict-flip-pause"):
        r = collect_episodes(
            CollectConfig(task="square-nut", operator=op, episodes=3, seed=7, batch=3)
        )
        parts.append(from_episodes(r.episodes, operators=op, obs_fields=task.obs_fields))
    contrast = concat_demos(parts)
    scores = score_demos(
        load_policy(d / "base_run").policy, contrast, ScoreConfig.from_preset("square-nut")
    )
    labels = {e: op == "same-style" for e, op in contrast.episode_operator().items()}
    fit = fit_thresholds(scores["likelihood"], scores["novelty"], contrast.episode, labels)
    assert fit.balanced_accuracy == 1.0
    return SessionInputs(d / "base.parquet", d / "base_run", *fit.thresholds.pair)
