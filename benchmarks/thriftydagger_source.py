"""ThriftyDAgger's 30 human Round Nut demonstrations: read, split, rebuilt in robosuite 1.5.

The paper's Round Nut study takes one operator's offline demonstrations from the public
ThriftyDAgger repository (github.com/ryanhoque/thriftydagger, file ``robosuite-30.pkl``; the
repository states no licence, so the file is not committed: pass a local copy). Its format,
read from the repository's collection code:

- a pickle of ``{"obs": (N, 51) float64, "act": (N, 7) float64}``, the 30 successful
  episodes stacked with no episode boundaries (failed episodes were discarded);
- recorded in robosuite 1.2.0's ``NutAssembly`` with one round nut (``single_object_mode=2``,
  ``nut_type="round"``: what robosuite 1.5 calls ``NutAssemblyRound``), robot **UR5e**
  (Robotiq 85 gripper), ``OSC_POSE`` at 20 Hz, keyboard teleoperation;
- one recorded step is one action followed by 10 control ticks that hold the arm still and
  keep the gripper command (about 1.8 recorded steps per second), with the x/y rotation
  components zeroed before they reach the controller;
- the observation is robosuite 1.2's ``GymWrapper`` vector: ``object-state`` (round nut
  position, quaternion xyzw, nut-to-eef position, nut-to-eef quaternion) then
  ``robot0_proprio-state`` (6 joint cosines, 6 sines, 6 joint velocities, eef position, eef
  quaternion, 6 gripper joint positions, 6 gripper joint velocities) -- :data:`LAYOUT`.

Episodes are found where the nut jumps between consecutive observations (a new episode puts
it back on the table, at least 34 cm from the peg where the previous one ended). Every
observation is rebuilt as a MuJoCo state of robosuite 1.5's ``NutAssemblyRound`` with a UR5e
(arm angles from the cosines and sines, gripper joints, nut pose, velocities) and this
project's observations are read from it.
"""

from __future__ import annotations

import hashlib
import io
import json
import pickle
import subprocess
import sys
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

SOURCE_REPO = "https://github.com/ryanhoque/thriftydagger"
SOURCE_COMMIT = "5f4aec2db6b6860620fb8cd9c486bbaef878c07a"
SOURCE_PATH = "robosuite-30.pkl"
SOURCE_SHA256 = "c63eb34bd06dc0e02dd983d57f0f533757ce576bc78efd8f9eaae9dfd8df80cb"
N_EPISODES = 30
HOLD_TICKS = 10
"""Control ticks after each recorded action that hold the arm (the recorder's wrapper)."""
JUMP_M = 0.2
"""A nut moving more than this between two recorded steps starts a new episode (m)."""
LAYOUT = {
    "nut_pos": (0, 3), "nut_quat": (3, 7), "nut_to_eef_pos": (7, 10),
    "nut_to_eef_quat": (10, 14), "joint_cos": (14, 20), "joint_sin": (20, 26),
    "joint_vel": (26, 32), "eef_pos": (32, 35), "eef_quat": (35, 39),
    "gripper_qpos": (39, 45), "gripper_qvel": (45, 51),
}  # fmt: skip
"""Slices of the recorded 51-value observation (robosuite 1.2 GymWrapper, UR5e, round nut)."""
OBS_DIM, ACT_DIM = 51, 7
OBS_KEYS = ("robot0_eef_pos", "robot0_eef_quat", "robot0_gripper_qpos", "object")
RECORDED = {"env_name": "NutAssemblyRound", "robot": "UR5e", "control_freq": 20}
TASK_ENV = {"env_name": "NutAssemblyRound", "robot": "Panda", "control_freq": 20}
"""The environment of the recording (as robosuite 1.5 names it) and of ``robosuite-round``."""


def fail(path: Path | str, problem: str) -> None:
    """Stop with a one-line error naming the file."""
    sys.exit(f"error: {path}: {problem}")


class _ArraysOnly(pickle.Unpickler):
    """Unpickles NumPy arrays in dicts and nothing else (a pickle can run any code)."""

    ALLOWED: ClassVar[set[tuple[str, str]]] = {
        ("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct"),
        ("numpy", "ndarray"), ("numpy", "dtype"),
    }  # fmt: skip

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) not in self.ALLOWED:
            raise pickle.UnpicklingError(f"refuses to load {module}.{name}")
        return super().find_class(module, name)


def source_bytes(path: Path) -> bytes:
    """The pickle's bytes from the file, a checkout holding it, or a (bare) git directory."""
    if not path.exists():
        fail(path, f"not found; pass a local copy of {SOURCE_PATH} from {SOURCE_REPO}")
    if path.is_file():
        return path.read_bytes()
    if (path / SOURCE_PATH).is_file():
        return (path / SOURCE_PATH).read_bytes()
    git = path / ".git" if (path / ".git").exists() else path
    if not (git / "HEAD").exists():
        fail(path, f"neither {SOURCE_PATH} nor a git directory holding it")
    run = subprocess.run(["git", f"--git-dir={git}", "show", f"HEAD:{SOURCE_PATH}"],
                         capture_output=True)  # fmt: skip
    if run.returncode:
        fail(path, f"its HEAD has no {SOURCE_PATH}")
    return run.stdout


def parse(data: bytes, path: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """``obs`` (N, 51) and ``act`` (N, 7) of the pickle, validated (errors name ``path``)."""
    try:
        d = _ArraysOnly(io.BytesIO(data)).load()
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError) as e:
        fail(path, f"not a ThriftyDAgger demo pickle ({e})")
    if not isinstance(d, dict) or not {"obs", "act"} <= set(d):
        fail(path, "expected a dict with 'obs' and 'act' arrays")
    obs, act = (np.asarray(d[k]) for k in ("obs", "act"))
    if obs.ndim != 2 or obs.shape[1] != OBS_DIM or act.ndim != 2 or act.shape[1] != ACT_DIM:
        fail(path, f"obs {obs.shape} / act {act.shape}: expected (N, {OBS_DIM}) / (N, {ACT_DIM})")
    if len(obs) != len(act) or len(obs) == 0:
        fail(path, f"{len(obs)} observations but {len(act)} actions")
    if not (np.isfinite(obs).all() and np.isfinite(act).all()):
        fail(path, "non-finite values in obs or act")
    return obs.astype(np.float64), act.astype(np.float64)


def read_source(path: Path, sha256: str | None = SOURCE_SHA256) -> tuple[np.ndarray, np.ndarray]:
    """The recorded arrays of ``path``; its SHA-256 checked unless ``sha256`` is ``None``."""
    data = source_bytes(path)
    got = hashlib.sha256(data).hexdigest()
    if sha256 is not None and got != sha256:
        fail(path, f"SHA-256 {got[:12]}… is not {sha256[:12]}… ({SOURCE_PATH} at "
             f"{SOURCE_COMMIT[:7]})")  # fmt: skip
    return parse(data, path)


def field(obs: np.ndarray, name: str) -> np.ndarray:
    """One named part of the recorded observations (:data:`LAYOUT`)."""
    a, b = LAYOUT[name]
    return obs[..., a:b]


def split_episodes(
    obs: np.ndarray, path: Path | str, expected: int | None
) -> list[tuple[int, int]]:
    """[start, stop) of each episode: a new one starts where the nut jumps (> ``JUMP_M``)."""
    jump = np.linalg.norm(np.diff(field(obs, "nut_pos"), axis=0), axis=1)
    cuts = np.flatnonzero(jump > JUMP_M) + 1
    starts, stops = np.r_[0, cuts], np.r_[cuts, len(obs)]
    spans = [(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]
    if expected is not None and len(spans) != expected:
        fail(path, f"found {len(spans)} episodes (nut jumps), expected {expected}")
    if min(b - a for a, b in spans) < 2:
        fail(path, "an episode of fewer than 2 steps (nut jumps on consecutive steps)")
    return spans


def arm_angles(obs: np.ndarray) -> np.ndarray:
    """The UR5e's 6 joint angles from the recorded cosines and sines."""
    return np.arctan2(field(obs, "joint_sin"), field(obs, "joint_cos"))


def xyzw_to_wxyz(q: np.ndarray) -> np.ndarray:
    """robosuite's observation quaternion (x, y, z, w) as MuJoCo's (w, x, y, z)."""
    return np.concatenate([q[..., 3:], q[..., :3]], axis=-1)


def write_robomimic(
    path: Path, env: dict[str, Any], episodes: list[dict[str, np.ndarray]], source: dict[str, Any]
) -> None:
    """Episodes (``actions``, ``obs/<key>``, optional ``states``) as a robomimic file; the
    last step of each is marked a success (the recorder kept successful episodes only)."""
    import h5py

    env_args = {"env_name": env["env_name"], "type": 1, "env_kwargs": {
        "robots": [env["robot"]], "control_freq": env["control_freq"],
        "controller_configs": None}}  # fmt: skip
    tmp = path.with_suffix(".tmp.hdf5")
    with h5py.File(tmp, "w") as f:
        data = f.create_group("data")
        data.attrs["env_args"] = json.dumps(env_args)
        data.attrs["total"] = sum(len(e["actions"]) for e in episodes)
        data.attrs["source"] = json.dumps(source)
        for i, ep in enumerate(episodes):
            g = data.create_group(f"demo_{i}")
            n = len(ep["actions"])
            g.attrs["num_samples"] = n
            rewards = np.zeros(n)
            rewards[-1] = 1.0
            g["actions"], g["rewards"] = ep["actions"], rewards
            g["dones"] = (rewards > 0).astype(np.int64)
            if "states" in ep:
                g["states"] = ep["states"]
            for k, v in ep["obs"].items():
                g[f"obs/{k}"] = v
    tmp.replace(path)
