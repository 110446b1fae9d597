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

A robosuite task (``robosuite-square``, ``robosuite-round``) is drawn from its environment's
own ``MjModel`` with the task's ``scene_hints``: robosuite's arm and gripper are meshes, which
the page does not draw, so each of their links is drawn by its collision shape (one convex
mesh per link) as the box bounding that mesh; everything else (table, pegs, nuts, the
pedestal) keeps its primitives. Poses are streamed relative to the table top, so the page's
camera, grid and top view find the workspace where they find it in the other tasks.
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
MESH = 7


def _rgba(m: Any, kind: str, i: int, colours: dict[str, Any]) -> np.ndarray:
    """An item's colour: its own (or its material's); a hinted colour by body (or item) name
    prefix replaces it, except on an item hidden by a zero alpha (robosuite's sites)."""
    rgba = np.asarray(getattr(m, f"{kind}_rgba")[i], float)
    matid = int(getattr(m, f"{kind}_matid")[i])
    if matid >= 0 and tuple(np.round(rgba, 6)) == DEFAULT_RGBA:
        rgba = np.asarray(m.mat_rgba[matid], float)
    if rgba[3] <= 0:
        return rgba
    body = m.body(int(getattr(m, f"{kind}_bodyid")[i])).name
    name = getattr(m, kind)(i).name
    for prefix, hinted in colours.items():
        if body.startswith(prefix) or name.startswith(prefix):
            return np.asarray(hinted, float)
    return rgba


def _item(m: Any, kind: str, i: int, colours: dict[str, Any]) -> dict[str, Any] | None:
    def get(attr: str) -> Any:
        return getattr(m, f"{kind}_{attr}")[i]

    type_id = int(get("type"))
    if int(get("group")) >= VISIBLE_GROUPS:
        return None
    pos, quat, size = get("pos"), get("quat"), get("size")
    if kind == "geom" and type_id == MESH and colours is not None:  # drawn as its bounding box
        import mujoco

        centre = np.zeros(3)
        mujoco.mju_rotVecQuat(centre, np.asarray(m.geom_aabb[i, :3], float), quat)
        type_id, pos, size = 6, pos + centre, m.geom_aabb[i, 3:]
    if type_id not in GEOM_TYPES:
        name = getattr(m, kind)(i).name or f"#{i}"
        raise ElicitError(
            f"{kind} '{name}' is of type {type_id} (mesh or height field): the browser view "
            "draws primitive geoms only"
        )
    rgba = _rgba(m, kind, i, colours or {})
    if rgba[3] <= 0:
        return None
    return {
        "name": getattr(m, kind)(i).name,
        "kind": kind,
        "type": GEOM_TYPES[type_id],
        "size": [float(v) for v in size],
        "rgba": [round(float(v), 4) for v in rgba],
        "body": int(get("bodyid")),
        "pos": [float(v) for v in pos],
        "quat": [float(v) for v in quat],
    }


def _collision_box_geoms(m: Any) -> list[int]:
    """Geoms drawn under ``meshes = collision-boxes``: a body with visual meshes (group >= 1)
    is drawn by its collision geoms (group 0, meshes as their bounding boxes); any other body
    by its visual geoms, or its collision geoms when it has none. Groups >= 2 are left out."""
    by_body: dict[int, list[int]] = {}
    for i in range(m.ngeom):
        by_body.setdefault(int(m.geom_bodyid[i]), []).append(i)
    out = []
    for geoms in by_body.values():
        visual = [i for i in geoms if int(m.geom_group[i]) == 1]
        collision = [i for i in geoms if int(m.geom_group[i]) == 0]
        meshy = any(int(m.geom_type[i]) == MESH for i in visual)
        out += collision if meshy or not visual else visual
    return sorted(out)


def scene_hints(task_name: str) -> dict[str, Any]:
    """How the browser draws task ``task_name`` (its ``scene_hints``; none for the tasks of
    this project's own MJCF, or an unknown name)."""
    from elicit_jax.sim.env import make_task

    try:
        return dict(getattr(make_task(task_name), "scene_hints", {}) or {})
    except ElicitError:
        return {}


def scene_description(
    model: Any, task_name: str = "", hints: dict[str, Any] | None = None
) -> dict[str, Any]:
    """What the browser needs to build the scene of ``model`` once.

    Args:
      model: the MuJoCo model.
      task_name: the task (its :func:`scene_hints` apply unless ``hints`` are given).
      hints: ``origin`` (the world point drawn at the origin: :func:`body_poses` subtracts
        it), ``home`` (the camera's home position and target), ``gripper`` (the body whose
        path the page draws), ``meshes`` (``collision-boxes``: see
        :func:`_collision_box_geoms`) and ``colours`` (RGBA by body or geom name prefix).

    Returns:
      ``{"task", "bodies": [names], "items": [geoms and sites], "center", "extent"}`` plus
      the hints ``origin``, ``home`` and ``gripper`` when given: each item has ``type``
      (plane, sphere, capsule, ellipsoid, cylinder, box), ``size`` (MuJoCo's size triple),
      ``rgba``, ``body`` (index into ``bodies``) and ``pos``/``quat`` (w, x, y, z) in the
      body's frame.

    Raises:
      ElicitError: a visible mesh or height-field geom (not drawn by the browser).
    """
    m = model
    hints = scene_hints(task_name) if hints is None else hints
    boxes = hints.get("meshes") == "collision-boxes"
    colours = dict(hints.get("colours") or {}) if boxes else None
    geoms = _collision_box_geoms(m) if boxes else range(m.ngeom)
    items = [_item(m, "geom", i, colours) for i in geoms]
    items += [_item(m, "site", i, colours) for i in range(m.nsite)]
    out = {
        "task": task_name,
        "bodies": [m.body(i).name for i in range(m.nbody)],
        "items": [it for it in items if it is not None],
        "center": [float(v) for v in m.stat.center],
        "extent": float(m.stat.extent),
    }
    for key in ("origin", "home", "gripper"):
        if key in hints:
            out[key] = hints[key]
    return out


def scene_origin(task: Any) -> np.ndarray:
    """(3,) the world point ``task``'s scene draws at the origin (zeros unless hinted)."""
    hints = getattr(task, "scene_hints", None) or {}
    return np.asarray(hints.get("origin", (0.0, 0.0, 0.0)), np.float64)


def body_poses(data: Any, origin: Any = None) -> np.ndarray:
    """(nbody, 7) float32 world poses ``(x, y, z, qw, qx, qy, qz)`` of ``data``'s bodies,
    positions relative to ``origin`` (3,) when given."""
    pos = data.xpos if origin is None else data.xpos - np.asarray(origin, np.float64)
    return np.concatenate([pos, data.xquat], axis=1).astype(np.float32)


def clip_from_actions(task: Any, init_seed: int, actions: np.ndarray) -> np.ndarray:
    """Poses ``(T + 1, nbody, 7)`` of ``actions (T, A)`` replayed from a seeded initial state.

    Row ``t`` is the state step ``t`` started from; the last row is the state after the
    last action. Poses come from the joint positions (as :func:`clip_from_states`).
    """
    from elicit_jax.sim.single import open_env

    qpos = []
    with open_env(task) as sim:
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
    Positions are relative to the task's :func:`scene_origin`.
    """
    import mujoco

    m = task.mj_model
    d = mujoco.MjData(m)
    origin = scene_origin(task)
    if m.nmocap and init_seed is not None and getattr(task, "backend", "") != "robosuite":
        _, mocap = task.init_states(np.array([init_seed]))
        d.mocap_pos[:] = mocap[0]
    out = []
    for q in np.asarray(qpos, np.float64):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        out.append(body_poses(d, origin))
    return np.stack(out) if out else np.zeros((0, m.nbody, 7), np.float32)


def clip_from_obs(task: Any, obs: np.ndarray) -> np.ndarray:
    """Poses ``(T, nbody, 7)`` of the gripper alone, from observations ``obs (T, 23)``.

    The gripper's joints are the first qpos entries of every task (x, y, z, yaw, fingers);
    everything else (objects, a goal marker) stays at the model's rest pose. A robosuite arm
    cannot be posed from its end effector's observation: its scene stands at rest.
    """
    from elicit_jax.sim.env import quat_yaw

    obs = np.asarray(obs, np.float64)
    qpos = np.tile(np.asarray(task.mj_model.qpos0, np.float64), (len(obs), 1))
    if getattr(task, "backend", "") == "robosuite":
        return clip_from_states(task, qpos)
    qpos[:, 0:3] = obs[:, 0:3]
    qpos[:, 3] = quat_yaw(obs[:, 3:7])
    qpos[:, 4:6] = obs[:, 7:9]
    return clip_from_states(task, qpos)
