"""Builders of small datasets in the real on-disk layouts (robomimic HDF5, LeRobot v2.1/v3.0).

Written independently of elicit_jax's own exporters, following the published layouts, so
that import tests check our readers against the formats rather than against ourselves.
"""

from __future__ import annotations

import json
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
            if "rewards" in d:
                g.create_dataset("rewards", data=d["rewards"])
            dones = np.zeros(t, np.int64)
            if t:
                dones[-1] = 1
            g.create_dataset("dones", data=dones)
            for key, arr in d.items():
                if key.startswith("obs/"):
                    g.create_dataset(key, data=arr)
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


def _frames_table(episodes: list[dict], start_index: int = 0):
    """LeRobot frame rows as HF ``datasets`` writes them (vectors as list<float32>)."""
    import pyarrow as pa

    cols: dict[str, list] = {
        k: []
        for k in (
            "observation.state",
            "action",
            "timestamp",
            "frame_index",
            "episode_index",
            "index",
            "task_index",
            "next.reward",
            "next.done",
            "next.success",
        )
    }
    index = start_index
    for ep in episodes:
        t = len(ep["state"])
        cols["observation.state"] += ep["state"].astype(np.float32).tolist()
        cols["action"] += ep["action"].astype(np.float32).tolist()
        cols["timestamp"] += (np.arange(t, dtype=np.float32) / 10).tolist()
        cols["frame_index"] += list(range(t))
        cols["episode_index"] += [ep["episode_index"]] * t
        cols["index"] += list(range(index, index + t))
        cols["task_index"] += [ep.get("task_index", 0)] * t
        cols["next.reward"] += ep["reward"].astype(np.float32).tolist()
        cols["next.done"] += [False] * (t - 1) + [True]
        cols["next.success"] += ep["success_flags"].tolist()
        index += t
    vec = pa.list_(pa.float32())
    types = {
        "observation.state": vec,
        "action": vec,
        "timestamp": pa.float32(),
        "next.reward": pa.float32(),
        "next.done": pa.bool_(),
        "next.success": pa.bool_(),
    }
    return pa.table({k: pa.array(v, types.get(k, pa.int64())) for k, v in cols.items()})


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


def _features() -> dict:
    def f(dtype: str, shape: list[int]) -> dict:
        return {"dtype": dtype, "shape": shape, "names": None}

    return {
        "observation.state": f("float32", [6]),
        "action": f("float32", [6]),
        "timestamp": f("float32", [1]),
        "frame_index": f("int64", [1]),
        "episode_index": f("int64", [1]),
        "index": f("int64", [1]),
        "task_index": f("int64", [1]),
        "next.reward": f("float32", [1]),
        "next.done": f("bool", [1]),
        "next.success": f("bool", [1]),
    }


def write_lerobot_v21(root: Path, episodes: list[dict], tasks: list[str], chunks_size=1000):
    """LeRobot codebase v2.1 folder: one Parquet per episode + jsonl metadata."""
    import pyarrow.parquet as pq

    root.mkdir(parents=True)
    n_frames = sum(len(e["state"]) for e in episodes)
    info = {
        "codebase_version": "v2.1",
        "robot_type": "so100",
        "total_episodes": len(episodes),
        "total_frames": n_frames,
        "total_tasks": len(tasks),
        "total_videos": 0,
        "total_chunks": 1,
        "chunks_size": chunks_size,
        "fps": 10,
        "splits": {"train": f"0:{len(episodes)}"},
        "data_path": "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet",
        "video_path": None,
        "features": _features(),
    }
    (root / "meta").mkdir()
    (root / "meta" / "info.json").write_text(json.dumps(info, indent=4))
    index, lines = 0, []
    for ep in episodes:
        e = ep["episode_index"]
        path = root / "data" / f"chunk-{e // chunks_size:03d}" / f"episode_{e:06d}.parquet"
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(_frames_table([ep], index), path)
        index += len(ep["state"])
        task = tasks[ep.get("task_index", 0)]
        lines.append({"episode_index": e, "tasks": [task], "length": len(ep["state"])})
    (root / "meta" / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in lines))
    (root / "meta" / "tasks.jsonl").write_text(
        "".join(json.dumps({"task_index": i, "task": t}) + "\n" for i, t in enumerate(tasks))
    )
    return root


def write_lerobot_v30(root: Path, episodes: list[dict], tasks: list[str], per_file: int = 2):
    """LeRobot codebase v3.0 folder: several episodes per data file, Parquet metadata."""
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
        "video_path": None,
        "features": _features(),
    }
    (root / "meta" / "episodes" / "chunk-000").mkdir(parents=True)
    (root / "data" / "chunk-000").mkdir(parents=True)
    (root / "meta" / "info.json").write_text(json.dumps(info, indent=4))
    records, index = [], 0
    for file_index in range(0, len(episodes), per_file):
        group = episodes[file_index : file_index + per_file]
        table = _frames_table(group, index)
        pq.write_table(
            table, root / "data" / "chunk-000" / f"file-{file_index // per_file:03d}.parquet"
        )
        for ep in group:
            t = len(ep["state"])
            records.append(
                {
                    "episode_index": ep["episode_index"],
                    "tasks": [tasks[ep.get("task_index", 0)]],
                    "length": t,
                    "data/chunk_index": 0,
                    "data/file_index": file_index // per_file,
                    "dataset_from_index": index,
                    "dataset_to_index": index + t,
                    "meta/episodes/chunk_index": 0,
                    "meta/episodes/file_index": 0,
                }
            )
            index += t
    pq.write_table(
        pa.Table.from_pylist(records), root / "meta" / "episodes" / "chunk-000" / "file-000.parquet"
    )
    df = pd.DataFrame({"task_index": list(range(len(tasks)))}, index=pd.Index(tasks, name="task"))
    df.to_parquet(root / "meta" / "tasks.parquet")
    return root
