"""The public human demonstration behind ``benchmarks/real_human.py``: read, cut, replayed.

robosuite 1.0.1's wheel on PyPI (MIT licence) ships one human teleoperated demonstration of
``NutAssembly`` (MuJoCo states and actions, no observations). This module reads it from the
wheel or the extracted ``demo.hdf5`` (SHA-256 checked), finds the steps where robosuite's own
check first sees each nut on its peg, cuts the single-nut segment of a task, reads robomimic's
low-dimensional observations by replaying the recorded states in robosuite 1.5, writes the
segment as a robomimic file, and checks how an open-loop replay of its actions drifts.
"""

from __future__ import annotations

import hashlib
import io
import json
import sys
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

SOURCE_URL = "https://pypi.org/project/robosuite/1.0.1/"
SOURCE_MEMBER = "robosuite/models/assets/demonstrations/nut-assembly/panda/demo.hdf5"
SOURCE_SHA256 = "876a5bc9fa6f05f9a3dcd9e0e4f05675f3c8fed76b61122a6ac17ddccd88ce86"
WHEEL_SHA256 = "92d45d7ad57e6d8a63becc96d14a038e17ab1919c00d771a4bbb6e6fc7aa4810"
OBS_KEYS = ("robot0_eef_pos", "robot0_eef_quat", "robot0_gripper_qpos", "object")
TASKS = {"robosuite-square": ("NutAssemblySquare", 0), "robosuite-round": ("NutAssemblyRound", 1)}
"""task -> (robosuite environment, index of its nut in robosuite's ``objects_on_pegs``)."""


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def read_source(path: Path) -> bytes:
    """The demo file's bytes from the wheel or the extracted file; its hash checked."""
    if not path.exists():
        sys.exit(
            f"error: {path}: not found. Download the source first (PyPI, MIT licence):\n"
            f"  pip download --no-deps robosuite==1.0.1 -d DIR   ({SOURCE_URL})\n"
            f"and pass DIR/robosuite-1.0.1-py3-none-any.whl (or its {SOURCE_MEMBER})."
        )
    if zipfile.is_zipfile(path):
        with zipfile.ZipFile(path) as z:
            if SOURCE_MEMBER not in z.namelist():
                sys.exit(f"error: {path}: no {SOURCE_MEMBER} in this wheel (robosuite 1.0.1?)")
            data = z.read(SOURCE_MEMBER)
    else:
        data = path.read_bytes()
    if sha256(data) != SOURCE_SHA256:
        sys.exit(f"error: {path}: demo SHA-256 {sha256(data)[:12]}… is not {SOURCE_SHA256[:12]}…")
    return data


def load_demo(data: bytes) -> dict[str, Any]:
    """States, actions and recording metadata of the (single) demonstration."""
    import h5py

    with h5py.File(io.BytesIO(data), "r") as f:
        names = sorted(f["data"].keys())
        if len(names) != 1:
            sys.exit(f"error: expected one demonstration, found {names}")
        g = f["data"][names[0]]
        return {
            "name": names[0],
            "states": np.asarray(g["states"], dtype=np.float64),
            "actions": np.asarray(g["actions"], dtype=np.float64),
            "env_info": json.loads(f["data"].attrs["env_info"]),
            "date": str(f["data"].attrs["date"]),
            "repository_version": str(f["data"].attrs["repository_version"]),
        }


def set_state(env: Any, state: np.ndarray) -> None:
    """Put robosuite's simulation in a recorded ``[time, qpos, qvel]`` state."""
    sim = env.sim
    nq, nv = sim.model.nq, sim.model.nv
    if state.size != 1 + nq + nv:
        sys.exit(f"error: state has {state.size} values, this model needs 1 + {nq} + {nv}")
    sim.data.qpos[:] = state[1 : 1 + nq]
    sim.data.qvel[:] = state[1 + nq :]
    sim.forward()


def placements(states: np.ndarray) -> tuple[int, int]:
    """First step at which robosuite's check sees the square / the round nut on its peg."""
    from elicit_jax.sim.robosuite_env import make_env, spec_for

    env = make_env(spec_for("NutAssembly", OBS_KEYS), horizon=len(states) + 1)
    env.reset()
    on = np.zeros((len(states), 2), dtype=bool)
    for t, s in enumerate(states):
        set_state(env, s)
        env._check_success()
        on[t] = np.asarray(env.objects_on_pegs, dtype=bool)[:2]
    env.close()
    if not on.any(axis=0).all():
        sys.exit("error: the demonstration does not put both nuts on their pegs")
    first = on.argmax(axis=0)
    return int(first[0]), int(first[1])


def cut(task: str, states: np.ndarray) -> tuple[int, int]:
    """The [start, stop) steps of ``task``'s segment (the task's nut placed second or first)."""
    square_at, round_at = placements(states)
    if round_at >= square_at:
        sys.exit("error: this script expects the round nut placed first (the robosuite 1.0.1 demo)")
    return (round_at + 1, square_at + 1) if task == "robosuite-square" else (0, round_at + 1)


def observe(task: str, states: np.ndarray) -> dict[str, np.ndarray]:
    """robomimic's low-dim observations of each state, read in the task's environment."""
    from elicit_jax.sim.robosuite_env import ROBOMIMIC_KEY_ALIASES, make_env, spec_for

    env = make_env(spec_for(TASKS[task][0], OBS_KEYS), horizon=len(states) + 1)
    env.reset()
    out: dict[str, list[np.ndarray]] = {k: [] for k in OBS_KEYS}
    done = np.zeros(len(states), dtype=bool)
    for t, s in enumerate(states):
        set_state(env, s)
        obs = env._get_observations(force_update=True)
        for k in OBS_KEYS:
            out[k].append(np.ravel(obs[ROBOMIMIC_KEY_ALIASES.get(k, k)]).astype(np.float64))
        done[t] = bool(env._check_success())
    env.close()
    if not done[-1]:
        sys.exit(f"error: the {task} segment does not end in robosuite's success")
    return {k: np.stack(v) for k, v in out.items()}


def write_robomimic(path: Path, task: str, demo: dict[str, Any], span: tuple[int, int]) -> None:
    """The segment as a one-demo robomimic file (reward 1 at its last step: success)."""
    import h5py

    s, e = span
    states, actions = demo["states"][s:e], demo["actions"][s:e]
    obs = observe(task, states)
    env_kwargs = {
        "robots": ["Panda"],
        "control_freq": 20,
        "controller_configs": demo["env_info"]["controller_configs"],
    }
    rewards = np.zeros(e - s)
    rewards[-1] = 1.0
    tmp = path.with_suffix(".tmp.hdf5")
    with h5py.File(tmp, "w") as f:
        data = f.create_group("data")
        data.attrs["env_args"] = json.dumps(
            {"env_name": TASKS[task][0], "type": 1, "env_kwargs": env_kwargs}
        )
        data.attrs["total"] = e - s
        data.attrs["source"] = json.dumps(
            {
                "url": SOURCE_URL,
                "member": SOURCE_MEMBER,
                "sha256": SOURCE_SHA256,
                "demo": demo["name"],
                "steps": [s, e],
                "recorded": demo["date"],
                "robosuite_version": demo["repository_version"],
            }
        )
        g = data.create_group("demo_0")
        g.attrs["num_samples"] = e - s
        g["actions"], g["states"], g["rewards"] = actions, states, rewards
        g["dones"] = (rewards > 0).astype(np.int64)
        for k, v in obs.items():
            g[f"obs/{k}"] = v
    tmp.replace(path)


def replay_check(task: str, human: Path) -> dict[str, Any]:
    """Open-loop replay of the human's actions in robosuite 1.5 from the segment's first
    recorded state: how far the hand drifts from the recorded one, and whether it succeeds."""
    import h5py

    from elicit_jax.sim.robosuite_env import make_env, spec_for

    with h5py.File(human, "r") as f:
        g = f["data/demo_0"]
        states, actions = g["states"][:], g["actions"][:]
        eef = g["obs/robot0_eef_pos"][:]
    env = make_env(spec_for(TASKS[task][0], OBS_KEYS), horizon=len(states) + 1)
    env.reset()
    set_state(env, states[0])
    err, ok = [], False
    for t in range(len(actions) - 1):
        obs, *_ = env.step(actions[t])
        err.append(float(np.linalg.norm(obs["robot0_eef_pos"] - eef[t + 1])))
        ok = ok or bool(env._check_success())
    env.close()
    return {"err_50": max(err[:50]), "err_max": max(err), "success": ok}
