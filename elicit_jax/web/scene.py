"""The 3-D scene a browser draws: geoms described once, body poses streamed per step.

No rendering happens on the server. :func:`scene_description` turns a MuJoCo model into a
small JSON-ready description — every visible geom and site with its primitive type, size,
colour, the body it hangs on and its pose in that body — which the browser builds into a
three.js scene once. After that only body poses move: :func:`body_poses` reads them from an
``MjData`` as ``(nbody, 7)`` float32 rows ``(x, y, z, qw, qx, qy, qz)`` in the world frame,
which :mod:`elicit_jax.web.protocol` packs into compact binary frames.

Clips (pose sequences ``(T, nbody, 7)``) replay episodes in the browser:
:func:`clip_from_actions` re-simulates a base demonstration from its seeded initial state
(C MuJoCo is deterministic, so it is the recorded motion), :func:`clip_from_states` poses a
recorded session episode from its per-step ``qpos``, and :func:`clip_from_obs` poses the
gripper alone from observations when a base demonstration carries no initial-state seed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError

GEOM_TYPES = {0: "plane", 2: "sphere", 3: "capsule", 4: "ellipsoid", 5: "cylinder", 6: "box"}
"""MuJoCo geom type ids the browser draws (primitives; meshes and height fields are not)."""
VISIBLE_GROUPS = 3
"""Geom and site groups 0-2 are drawn, as in MuJoCo's own viewer."""
DEFAULT_RGBA = (0.5, 0.5, 0.5, 1.0)


def _item(m: Any, kind: str, i: int) -> dict[str, Any] | None:
    def get(attr: str) -> Any:
        return getattr(m, f"{kind}_{attr}")[i]

    type_id = int(get("type"))
    if int(get("group")) >= VISIBLE_GROUPS:
        return None
    if type_id not in GEOM_TYPES:
        name = getattr(m, kind)(i).name or f"#{i}"
        raise ElicitError(
            f"{kind} '{name}' is of type {type_id} (mesh or height field): the browser view "
            "draws primitive geoms only"
        )
    rgba = np.asarray(get("rgba"), float)
    matid = int(get("matid"))
    if matid >= 0 and tuple(np.round(rgba, 6)) == DEFAULT_RGBA:
        rgba = np.asarray(m.mat_rgba[matid], float)
    if rgba[3] <= 0:
        return None
    return {
        "name": getattr(m, kind)(i).name,
        "kind": kind,
        "type": GEOM_TYPES[type_id],
        "size": [float(v) for v in get("size")],
        "rgba": [round(float(v), 4) for v in rgba],
        "body": int(get("bodyid")),
        "pos": [float(v) for v in get("pos")],
        "quat": [float(v) for v in get("quat")],
    }


def scene_description(model: Any, task_name: str = "") -> dict[str, Any]:
    """What the browser needs to build the scene of ``model`` once.

    Returns:
      ``{"task", "bodies": [names], "items": [geoms and sites], "timestep", "extent",
      "center"}``: each item has ``type`` (plane, sphere, capsule, ellipsoid, cylinder,
      box), ``size`` (MuJoCo's size triple), ``rgba``, ``body`` (index into ``bodies``) and
      ``pos``/``quat`` (w, x, y, z) in the body's frame.

    Raises:
      ElicitError: a visible mesh or height-field geom (not drawn by the browser).
    """
    m = model
    items = [_item(m, "geom", i) for i in range(m.ngeom)]
    items += [_item(m, "site", i) for i in range(m.nsite)]
    return {
        "task": task_name,
        "bodies": [m.body(i).name for i in range(m.nbody)],
        "items": [it for it in items if it is not None],
        "center": [float(v) for v in m.stat.center],
        "extent": float(m.stat.extent),
    }


def body_poses(data: Any) -> np.ndarray:
    """(nbody, 7) float32 world poses ``(x, y, z, qw, qx, qy, qz)`` of ``data``'s bodies."""
    return np.concatenate([data.xpos, data.xquat], axis=1).astype(np.float32)


def clip_from_actions(task: Any, init_seed: int, actions: np.ndarray) -> np.ndarray:
    """Poses ``(T + 1, nbody, 7)`` of ``actions (T, A)`` replayed from a seeded initial state.

    Row ``t`` is the state step ``t`` started from; the last row is the state after the
    last action. Poses come from the joint positions (as :func:`clip_from_states`).
    """
    from elicit_jax.sim.rollout_mujoco import BatchSim

    qpos = []
    with BatchSim(task, 1, threads=1) as sim:
        sim.reset_seeds(np.array([init_seed]))
        for a in np.asarray(actions, np.float64):
            qpos.append(sim.datas[0].qpos.copy())
            sim.step(a[None])
        qpos.append(sim.datas[0].qpos.copy())
    return clip_from_states(task, np.stack(qpos), init_seed)


def clip_from_states(task: Any, qpos: np.ndarray, init_seed: int | None = None) -> np.ndarray:
    """Poses ``(T, nbody, 7)`` at recorded joint positions ``qpos (T, nq)`` (kinematics only).

    Mocap bodies (such as a goal marker) are not joints: they are put where the seeded
    initial state ``init_seed`` put them, or left at the model's rest pose without one.
    """
    import mujoco

    m = task.mj_model
    d = mujoco.MjData(m)
    if m.nmocap and init_seed is not None:
        _, mocap = task.init_states(np.array([init_seed]))
        d.mocap_pos[:] = mocap[0]
    out = []
    for q in np.asarray(qpos, np.float64):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        out.append(body_poses(d))
    return np.stack(out) if out else np.zeros((0, m.nbody, 7), np.float32)


def clip_from_obs(task: Any, obs: np.ndarray) -> np.ndarray:
    """Poses ``(T, nbody, 7)`` of the gripper alone, from observations ``obs (T, 23)``.

    The gripper's joints are the first qpos entries of every task (x, y, z, yaw, fingers);
    everything else (objects, a goal marker) stays at the model's rest pose.
    """
    from elicit_jax.sim.env import quat_yaw

    obs = np.asarray(obs, np.float64)
    qpos = np.tile(np.asarray(task.mj_model.qpos0, np.float64), (len(obs), 1))
    qpos[:, 0:3] = obs[:, 0:3]
    qpos[:, 3] = quat_yaw(obs[:, 3:7])
    qpos[:, 4:6] = obs[:, 7:9]
    return clip_from_states(task, qpos)
