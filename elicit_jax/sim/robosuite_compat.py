"""Make robosuite 1.5 run on the MuJoCo this project pins (3.17).

robosuite 1.5.x was written against MuJoCo 3.2/3.3. Two of its calls break on MuJoCo 3.17,
and both break every robosuite environment at its first reset or step:

1. ``MjModel.get_joint_qpos_addr`` / ``get_joint_qvel_addr`` check a joint's type with
   ``joint_type in (mjtJoint.mjJNT_HINGE, mjtJoint.mjJNT_SLIDE)``. ``joint_type`` is a NumPy
   integer read from ``model.jnt_type``; with MuJoCo 3.17's enum type that membership test is
   False for every joint, so the assertion fails on the first robot joint. Adapted: both
   methods are replaced by ones that compare ``int(joint_type)`` with the enum's integers
   (same addresses, same return shapes).
2. ``Controller.update`` computes the mass matrix with ``mujoco.mj_fullM(model, dst,
   data.qM)``. MuJoCo 3.17 has no ``MjData.qM`` and ``mj_fullM`` takes ``(model, data,
   dst)``. Adapted: robosuite's ``MjData`` wrapper gains a ``qM`` attribute that hands back
   the raw ``mujoco.MjData``, and the controller module sees a ``mujoco`` whose ``mj_fullM``
   accepts the old argument order and calls the new one (everything else is MuJoCo itself).

Each patch is applied only when its breakage is detected by behaviour (the membership test
fails; ``mujoco.MjData`` has no ``qM``), once per process (:func:`ensure_compat` is
idempotent), and only by the robosuite backend, right after it imports robosuite: nothing
changes for a process that never asks for a robosuite task.
"""

from __future__ import annotations

import types
from typing import Any

_MARK = "_elicit_jax_compat"


def joint_enum_broken() -> bool:
    """Whether ``numpy_int in (mjtJoint..., ...)`` fails (the check robosuite relies on)."""
    import mujoco
    import numpy as np

    hinge = mujoco.mjtJoint.mjJNT_HINGE
    return np.int32(int(hinge)) not in (hinge, mujoco.mjtJoint.mjJNT_SLIDE)


def fullm_changed() -> bool:
    """Whether MuJoCo dropped ``MjData.qM`` (and ``mj_fullM`` reads the data itself)."""
    import mujoco

    return not hasattr(mujoco.MjData, "qM")


def _joint_addr(model: Any, name: str, first: Any, free_dim: int, ball_dim: int) -> Any:
    """The qpos/qvel address of joint ``name``: an int for 1-dof joints, else (start, end)."""
    import mujoco

    jid = model.joint_name2id(name)
    kind = int(model.jnt_type[jid])
    start = int(first[jid])
    t = mujoco.mjtJoint
    if kind == int(t.mjJNT_FREE):
        return (start, start + free_dim)
    if kind == int(t.mjJNT_BALL):
        return (start, start + ball_dim)
    if kind not in (int(t.mjJNT_HINGE), int(t.mjJNT_SLIDE)):
        raise ValueError(f"joint {name!r} has unknown type {kind}")
    return start


def get_joint_qpos_addr(self: Any, name: str) -> Any:
    """robosuite's ``MjModel.get_joint_qpos_addr`` with integer joint types."""
    return _joint_addr(self, name, self.jnt_qposadr, 7, 4)


def get_joint_qvel_addr(self: Any, name: str) -> Any:
    """robosuite's ``MjModel.get_joint_qvel_addr`` with integer joint types."""
    return _joint_addr(self, name, self.jnt_dofadr, 6, 3)


def _mujoco_with_old_fullm() -> types.ModuleType:
    """A module standing for ``mujoco`` whose ``mj_fullM`` takes ``(m, dst, data)``."""
    import mujoco

    proxy = types.ModuleType("mujoco", "mujoco, with mj_fullM taking robosuite's argument order")
    proxy.__dict__.update({k: v for k, v in vars(mujoco).items() if not k.startswith("__")})

    def mj_fullM(m: Any, dst: Any, src: Any) -> None:
        if isinstance(src, mujoco.MjData):
            mujoco.mj_fullM(m, src, dst)
        else:
            mujoco.mj_fullM(m, dst, src)

    proxy.mj_fullM = mj_fullM  # type: ignore[attr-defined]
    return proxy


def ensure_compat() -> list[str]:
    """Apply the adaptations this MuJoCo needs to robosuite (once per process).

    Returns:
      names of the adaptations in force (empty when robosuite runs as shipped).
    """
    from robosuite.controllers.parts import controller
    from robosuite.utils import binding_utils

    done = getattr(binding_utils, _MARK, None)
    if done is not None:
        return list(done)
    applied = []
    if joint_enum_broken():
        binding_utils.MjModel.get_joint_qpos_addr = get_joint_qpos_addr
        binding_utils.MjModel.get_joint_qvel_addr = get_joint_qvel_addr
        applied.append("joint-type")
    if fullm_changed():
        binding_utils.MjData.qM = property(lambda self: self._data)
        controller.mujoco = _mujoco_with_old_fullm()
        applied.append("mj_fullM")
    setattr(binding_utils, _MARK, tuple(applied))
    return applied
