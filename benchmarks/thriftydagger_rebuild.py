"""ThriftyDAgger's recorded observations rebuilt as robosuite 1.5 states, and replayed.

Each recorded observation of ``benchmarks/thriftydagger_source.py`` is set as a MuJoCo state of
robosuite 1.5's ``NutAssemblyRound`` with the recording's UR5e: arm angles (from the cosines
and sines), arm velocities, the 6 Robotiq joint positions and velocities, the nut's pose (its
velocity is not recorded: zero). From that state robosuite 1.5 computes this project's
observations (``robot0_eef_pos``, ``robot0_eef_quat``, ``robot0_gripper_qpos``, ``object``);
the recomputed end-effector pose is compared with the recorded one (fidelity).

``robosuite-round`` runs a Panda, so its 23-value observation has 2 gripper values where the
UR5e's has 6. The ``panda_view`` of a step keeps the end-effector pose and ``object`` (robosuite
places the end-effector frame at the gripper's grip site for both robots, with the same offset
from the hand body: a pose means the same gripper placement) and replaces the Robotiq joints by
the Panda finger positions that open the fingertip pads as far apart (clipped to the Panda's
joint range: the Robotiq opens wider).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from thriftydagger_source import (
    HOLD_TICKS,
    OBS_KEYS,
    RECORDED,
    TASK_ENV,
    arm_angles,
    field,
    xyzw_to_wxyz,
)


def make(env: dict[str, Any], horizon: int = 10_000) -> Any:
    """A reset robosuite 1.5 environment of ``env`` (``RECORDED`` or ``TASK_ENV``)."""
    from elicit_jax.sim.robosuite_env import make_env, reset_seeded, spec_for

    e = make_env(spec_for(env["env_name"], OBS_KEYS, robot=env["robot"],
                          control_freq=env["control_freq"]), horizon=horizon)  # fmt: skip
    reset_seeded(e, 0)
    return e


def _addr(sim: Any, joints: list[str], kind: str) -> np.ndarray:
    get = sim.model.get_joint_qpos_addr if kind == "qpos" else sim.model.get_joint_qvel_addr
    return np.array([get(j) for j in joints])


def set_recorded(env: Any, row: np.ndarray) -> None:
    """Put the simulation in the state of one recorded 51-value observation."""
    sim, robot = env.sim, env.robots[0]
    grip = robot.gripper["right"].joints
    nut = next(j for j in sim.model.joint_names if j.startswith("RoundNut"))
    qa, va = sim.model.get_joint_qpos_addr(nut), sim.model.get_joint_qvel_addr(nut)
    sim.data.qpos[_addr(sim, robot.robot_joints, "qpos")] = arm_angles(row)
    sim.data.qvel[_addr(sim, robot.robot_joints, "qvel")] = field(row, "joint_vel")
    sim.data.qpos[_addr(sim, grip, "qpos")] = field(row, "gripper_qpos")
    sim.data.qvel[_addr(sim, grip, "qvel")] = field(row, "gripper_qvel")
    sim.data.qpos[qa[0] : qa[0] + 3] = field(row, "nut_pos")
    sim.data.qpos[qa[0] + 3 : qa[0] + 7] = xyzw_to_wxyz(field(row, "nut_quat"))
    sim.data.qvel[va[0] : va[1]] = 0.0
    sim.forward()


def pad_distance(env: Any) -> float:
    """Distance between the gripper's two fingertip pads (m)."""
    sim, g = env.sim, env.robots[0].gripper["right"]
    pads = [sim.data.geom_xpos[[sim.model.geom_name2id(n) for n in g.important_geoms[k]]].mean(0)
            for k in ("left_fingerpad", "right_fingerpad")]  # fmt: skip
    return float(np.linalg.norm(pads[0] - pads[1]))


def panda_fingers() -> tuple[float, float, float]:
    """The Panda's pad distance at finger position 0, its slope per unit of finger position
    (both fingers move), and the fingers' upper joint limit -- measured in robosuite 1.5."""
    env = make(TASK_ENV)
    sim, g = env.sim, env.robots[0].gripper["right"]
    adr = _addr(sim, g.joints, "qpos")
    hi = float(sim.model.jnt_range[sim.model.joint_name2id(g.joints[0])][1])
    dist = []
    for q in (0.0, hi):
        sim.data.qpos[adr] = [q, -q]
        sim.forward()
        dist.append(pad_distance(env))
    env.close()
    return dist[0], (dist[1] - dist[0]) / hi, hi


def quat_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between unit quaternions (rad), sign-insensitive."""
    dot = np.abs(np.sum(a * b, axis=-1)).clip(0.0, 1.0)
    return 2.0 * np.arccos(dot)


def rebuild(obs: np.ndarray) -> dict[str, Any]:
    """Every recorded step as a robosuite 1.5 UR5e state: its observations (``ur5e``), their
    Panda view (``panda``), the flattened states and the fidelity of the rebuild."""
    d0, slope, hi = panda_fingers()
    env = make(RECORDED)
    keys = {"robot0_eef_pos": "robot0_eef_pos", "robot0_eef_quat": "robot0_eef_quat",
            "robot0_gripper_qpos": "robot0_gripper_qpos", "object": "object-state"}  # fmt: skip
    ur5e: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    states, pads = [], []
    for row in obs:
        set_recorded(env, row)
        o = env._get_observations(force_update=True)
        for k, src in keys.items():
            ur5e[k].append(np.ravel(o[src]).astype(np.float64))
        states.append(np.asarray(env.sim.get_state().flatten(), dtype=np.float64))
        pads.append(pad_distance(env))
    env.close()
    out = {k: np.stack(v) for k, v in ur5e.items()}
    fingers = (np.asarray(pads) - d0) / slope
    clipped = float(((fingers < 0) | (fingers > hi)).mean())
    fingers = fingers.clip(0.0, hi)
    panda = {**out, "robot0_gripper_qpos": np.stack([fingers, -fingers], axis=1)}
    rel = out["object"][:, 0:7]
    rec_rel = np.concatenate([field(obs, "nut_to_eef_pos"), field(obs, "nut_to_eef_quat")], 1)
    fidelity = {
        "eef_pos_max_mm": 1000 * float(np.abs(out["robot0_eef_pos"] - field(obs, "eef_pos")).max()),
        "eef_quat_max_deg": float(np.degrees(quat_angle(out["robot0_eef_quat"],
                                                        field(obs, "eef_quat")).max())),
        "nut_pos_max_mm": 1000
        * float(np.abs(out["object"][:, 7:10] - field(obs, "nut_pos")).max()),
        "rel_differs": float((np.abs(rel - rec_rel).max(axis=1) > 1e-3).mean()),
        "fingers_clipped": clipped,
        "pad_range_mm": (1000 * min(pads), 1000 * max(pads)),
    }  # fmt: skip
    return {"ur5e": out, "panda": panda, "states": np.stack(states), "fidelity": fidelity}


def replay(obs: np.ndarray, act: np.ndarray, spans: list[tuple[int, int]]) -> dict[str, Any]:
    """Open-loop replay in robosuite 1.5 (UR5e) of each episode's recorded actions from its
    first recorded state, the recorder's way (action with x/y rotation zeroed, then
    ``HOLD_TICKS`` holding ticks): hand drift from the recorded path and robosuite's success."""
    env = make(RECORDED)
    drift, ok = [], []
    for a, b in spans:
        set_recorded(env, obs[a])
        err, success = [], False
        for t in range(a, b):
            step = act[t].copy()
            step[3:5] = 0.0
            o, *_ = env.step(step)
            hold = np.zeros(7)
            hold[-1] = act[t][-1]
            for _ in range(HOLD_TICKS):
                o, *_ = env.step(hold)
            success = success or bool(env._check_success())
            if t + 1 < b:
                err.append(
                    float(np.linalg.norm(o["robot0_eef_pos"] - field(obs[t + 1], "eef_pos")))
                )
        drift.append(max(err))
        ok.append(success)
    env.close()
    return {"drift_max_m": np.asarray(drift), "success": np.asarray(ok)}
