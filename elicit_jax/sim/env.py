"""Task definitions shared by both simulators: the env state, the task base class, task lookup.

A task is written for ONE environment. Its pure functions ``reset(rng) -> EnvState`` and
``step(state, action) -> EnvState`` run on MJX and are batched with ``jax.vmap`` by callers.
The pieces both backends share (initial-state sampling, action -> actuator targets,
observation from sensors, success) are written once over an array module ``xp`` (``numpy``
or ``jax.numpy``), so C MuJoCo and MJX roll out the same task definition.

Observation (23 values, robomimic-style names): ``robot0_eef_pos`` (3),
``robot0_eef_quat`` (4, w-x-y-z), ``robot0_gripper_qpos`` (2) and ``object`` (14: object
position and quaternion, then its position and quaternion in the end-effector frame; a task
may fill it otherwise and says so, e.g. ``hammer-drawer`` puts the drawer's handle and
opening in the last four values). It is the model's sensor data, which both simulators
compute identically.

Action (7 values in [-1, 1]): delta position (3, scaled by ``pos_scale`` metres per control
step), delta rotation as an axis-angle vector (3, scaled by ``rot_scale`` radians; only its z
component acts, on the wrist yaw: the floating jaw always points down), gripper (1: -1 open,
+1 closed). Each control step holds the targets for ``substeps`` physics steps.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, ClassVar

import numpy as np
from flax import struct

from elicit_jax.data.demos import ObsField, fields_from_sizes
from elicit_jax.errors import ElicitError
from elicit_jax.sim import mjcf
from elicit_jax.sim.registry import ACTION_DIM, OBS_DIM, TASKS, task_entry

WARP_LINES = ("Failed to import warp", "Failed to import mujoco_warp")


def import_mjx() -> Any:
    """``mujoco.mjx``, imported without the lines its optional Warp backend prints on stdout
    when Warp is not installed ("Failed to import warp: No module named 'warp'"): elicit-jax
    never uses Warp, and the stray line read as an error before a long compile. Anything
    else printed on import goes to the log."""
    import contextlib
    import io
    import logging
    import sys

    if "mujoco.mjx" in sys.modules:
        return sys.modules["mujoco.mjx"]
    with contextlib.redirect_stdout(io.StringIO()) as said:
        from mujoco import mjx
    for line in said.getvalue().splitlines():
        if line.strip() and not line.startswith(WARP_LINES):
            logging.getLogger(__name__).info("mujoco.mjx on import: %s", line)
    return mjx


OBS_FIELDS: tuple[ObsField, ...] = fields_from_sizes(
    [("robot0_eef_pos", 3), ("robot0_eef_quat", 4), ("robot0_gripper_qpos", 2), ("object", 14)]
)
ACTION_NAMES = ("dx", "dy", "dz", "droll", "dpitch", "dyaw", "gripper")
"""Names of the action dimensions (delta position, delta rotation, gripper)."""
N_GRIPPER_Q = 6


@struct.dataclass
class EnvState:
    """State of one environment (batch it with ``jax.vmap``).

    Attributes:
      data: the ``mjx.Data`` physics state.
      obs: (23,) observation after the last control step.
      reward: () sparse reward of the last control step (1.0 on success).
      success: () bool, the task is solved in the current state.
      done: () bool, the task has been solved at some step so far (frozen once true).
      steps: () int32 control steps taken.
    """

    data: Any
    obs: Any
    reward: Any
    success: Any
    done: Any
    steps: Any


@dataclasses.dataclass(frozen=True)
class TaskConfig:
    """Settings every task has; tasks subclass it to add randomisation ranges.

    Attributes:
      horizon: control steps per episode.
      substeps: physics steps per control step.
      timestep: physics timestep (s).
      pos_scale: metres per unit of the position action per control step.
      rot_scale: radians per unit of the rotation action per control step.
    """

    horizon: int = 200
    substeps: int = 10
    timestep: float = 0.005
    pos_scale: float = 0.02
    rot_scale: float = 0.15


class Task:
    """Base class of a manipulation task with the floating gripper.

    Subclasses set ``name`` and ``config_cls`` and implement :meth:`xml`,
    :meth:`sample_init` and :meth:`success_from_obs`. Host-side set-up (model compilation,
    name lookups, ``mjx.put_model``) happens once, outside jitted code.
    """

    name: ClassVar[str] = ""
    config_cls: ClassVar[type[TaskConfig]] = TaskConfig

    def __init__(self, config: TaskConfig | None = None) -> None:
        import mujoco

        self.config = config or self.config_cls()
        self.mj_model = mujoco.MjModel.from_xml_string(self.xml())
        m = self.mj_model
        self.nq, self.nmocap = int(m.nq), int(m.nmocap)
        self.ctrl_low = np.asarray(m.actuator_ctrlrange[:, 0], np.float32)
        self.ctrl_high = np.asarray(m.actuator_ctrlrange[:, 1], np.float32)
        names = [m.joint(i).name for i in range(N_GRIPPER_Q)]
        if tuple(names) != mjcf.GRIPPER_JOINTS + mjcf.FINGER_JOINTS:
            raise ElicitError(f"task {self.name}: gripper joints out of order: {names}")
        self.qpos0 = np.asarray(m.qpos0, np.float32)
        self.setup()

    def setup(self) -> None:
        """Task-specific host-side lookups (names to ids); runs once at construction."""

    @property
    def obs_fields(self) -> tuple[ObsField, ...]:
        return OBS_FIELDS

    @functools.cached_property
    def mjx_model(self) -> Any:
        """The model on the JAX device (built on first use, outside any trace)."""
        import jax

        mjx = import_mjx()

        with jax.ensure_compile_time_eval():
            return mjx.put_model(self.mj_model)

    # --- to implement -------------------------------------------------------------------------
    def xml(self) -> str:
        """The task's MJCF document."""
        raise ElicitError(f"task {type(self).__name__} defines no model")

    def sample_init(self, rng: Any) -> tuple[Any, Any]:
        """Randomised initial ``qpos (nq,)`` and ``mocap_pos (nmocap, 3)`` from a PRNG key."""
        raise ElicitError(f"task {type(self).__name__} defines no initial states")

    def success_from_obs(self, obs: Any, xp: Any = np) -> Any:
        """Whether ``obs (..., 23)`` is a solved state; ``xp`` is numpy or jax.numpy."""
        raise ElicitError(f"task {type(self).__name__} defines no success check")

    def gripper_and_object_qpos(
        self,
        rng: Any,
        x: tuple[float, float],
        y: tuple[float, float],
        yaw: tuple[float, float],
        z: float,
    ) -> Any:
        """``qpos (nq,)`` with the gripper at its start (xy jittered by the config's
        ``start_xy``, height ``start_z``, fingers open: an :class:`ObjectTaskConfig`) and the
        task's first free body (qpos 6:13) resting at ``z`` with x, y and yaw uniform in the
        given ranges; other joints at ``qpos0``. One uniform draw of (x, y, yaw, gripper dx,
        dy) from ``rng``."""
        import jax
        import jax.numpy as jnp

        c = self.config
        if not isinstance(c, ObjectTaskConfig):
            raise ElicitError(f"task {self.name}: its config has no gripper start")
        jitter = c.start_xy
        lo = jnp.array([x[0], y[0], yaw[0], -jitter, -jitter])
        hi = jnp.array([x[1], y[1], yaw[1], jitter, jitter])
        u = jax.random.uniform(rng, (5,), minval=lo, maxval=hi)
        qpos = jnp.asarray(self.qpos0)
        qpos = qpos.at[0:3].set(jnp.stack([u[3], u[4], jnp.asarray(c.start_z)]))
        qpos = qpos.at[4:6].set(mjcf.FINGER_OPEN)
        pos = jnp.stack([u[0], u[1], jnp.asarray(z)])
        return qpos.at[6:13].set(jnp.concatenate([pos, yaw_quat(u[2], jnp)]))

    # --- shared kernels -----------------------------------------------------------------------
    def ctrl_from_action(self, qpos: Any, action: Any, xp: Any = np) -> Any:
        """Actuator targets ``(..., 6)`` from gripper joints ``qpos (..., >=4)`` and ``action``.

        Position and yaw targets are the current joint values plus the scaled deltas; the
        rotation's z component turns the wrist, its x and y components are ignored (the jaw
        always points down).
        """
        cfg = self.config
        a = xp.clip(action, -1.0, 1.0)
        pos = qpos[..., 0:3] + a[..., 0:3] * cfg.pos_scale
        yaw = qpos[..., 3:4] + a[..., 5:6] * cfg.rot_scale
        finger = (1.0 - a[..., 6:7]) * (0.5 * mjcf.FINGER_OPEN)
        ctrl = xp.concatenate([pos, yaw, finger, finger], axis=-1)
        return xp.clip(ctrl, self.ctrl_low, self.ctrl_high)

    def obs_from_sensordata(self, sensordata: Any) -> Any:
        """Observation ``(..., 23)`` from the sensor data (the sensors are the observation)."""
        return sensordata[..., :OBS_DIM]

    def init_states(self, seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Initial ``qpos (B, nq)`` and ``mocap_pos (B, nmocap, 3)`` for integer seeds (host).

        Uses the same JAX sampler as :meth:`reset`, so both backends start identically.
        """
        qpos, mocap = self._sample_inits(np.asarray(seeds, np.uint32))
        return np.asarray(qpos, np.float64), np.asarray(mocap, np.float64)

    @functools.cached_property
    def _sample_inits(self) -> Any:
        """Jitted ``seeds (B,) uint32 -> (qpos (B, nq), mocap (B, nmocap, 3))``, built once."""
        import jax

        return jax.jit(lambda s: jax.vmap(self.sample_init)(jax.vmap(jax.random.PRNGKey)(s)))

    # --- MJX ----------------------------------------------------------------------------------
    def reset(self, rng: Any) -> EnvState:
        """Initial state of one environment from a PRNG key (pure; jit/vmap it)."""
        qpos, mocap = self.sample_init(rng)
        return self.reset_to(qpos, mocap)

    def reset_to(self, qpos: Any, mocap_pos: Any) -> EnvState:
        """State at ``qpos (nq,)`` and ``mocap_pos (nmocap, 3)`` at rest, sensors computed."""
        import jax.numpy as jnp

        mjx = import_mjx()

        m = self.mjx_model
        data = mjx.make_data(m)
        ctrl = self.ctrl_from_action(qpos[:N_GRIPPER_Q], jnp.zeros(ACTION_DIM).at[6].set(-1), jnp)
        data = data.replace(qpos=qpos, ctrl=ctrl)
        if self.nmocap:
            data = data.replace(mocap_pos=mocap_pos)
        data = mjx.forward(m, data)
        obs = self.obs_from_sensordata(data.sensordata)
        success = self.success_from_obs(obs, jnp)
        return EnvState(
            data=data,
            obs=obs,
            reward=jnp.zeros(()),
            success=success,
            done=success,
            steps=jnp.zeros((), jnp.int32),
        )

    def step(self, state: EnvState, action: Any) -> EnvState:
        """One control step: set targets from ``action (7,)``, run the physics substeps."""
        import jax
        import jax.numpy as jnp

        mjx = import_mjx()

        m = self.mjx_model
        ctrl = self.ctrl_from_action(state.data.qpos[:N_GRIPPER_Q], action, jnp)
        data = state.data.replace(ctrl=ctrl)
        data = jax.lax.fori_loop(0, self.config.substeps, lambda _, d: mjx.step(m, d), data)
        obs = self.obs_from_sensordata(data.sensordata)
        success = self.success_from_obs(obs, jnp)
        return EnvState(
            data=data,
            obs=obs,
            reward=success.astype(jnp.float32),
            success=success,
            done=state.done | success,
            steps=state.steps + 1,
        )


@dataclasses.dataclass(frozen=True)
class ObjectTaskConfig(TaskConfig):
    """Settings of a task whose object :meth:`Task.gripper_and_object_qpos` places: the
    gripper's start; tasks subclass it to add the object's ranges.

    Attributes:
      start_xy: half-width of the gripper's initial xy jitter around (0, 0).
      start_z: gripper's initial height.
    """

    start_xy: float = 0.02
    start_z: float = 0.15


def quat_yaw(q: Any, xp: Any = np) -> Any:
    """Yaw angle (rad) of w-x-y-z quaternions ``q (..., 4)``."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return xp.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def yaw_quat(yaw: Any, xp: Any = np) -> Any:
    """w-x-y-z quaternions ``(..., 4)`` of rotations by ``yaw`` about z."""
    zero = xp.zeros_like(yaw)
    return xp.stack([xp.cos(yaw / 2), zero, zero, xp.sin(yaw / 2)], axis=-1)


def task_class(name: str) -> type[Task]:
    """The task class of task ``name`` (its registry entry's factory, imported here).

    Raises:
      ElicitError: unknown task name.
    """
    import importlib

    module, cls = task_entry(name).factory.split(":")
    return getattr(importlib.import_module(f"elicit_jax.sim.tasks.{module}"), cls)


def task_names() -> list[str]:
    """Names of the registered tasks (:data:`elicit_jax.sim.registry.TASKS`), sorted."""
    return sorted(TASKS)


@functools.lru_cache(maxsize=16)
def _make_cached(name: str, config: TaskConfig | None) -> Task:
    return task_class(name)(config)


def make_task(name: str, config: TaskConfig | None = None, **overrides: Any) -> Task:
    """Build (once per name and config) the task ``name``; ``overrides`` replace config fields.

    Raises:
      ElicitError: unknown task name or config field.
    """
    cls = task_class(name)
    if overrides:
        base = config or cls.config_cls()
        known = {f.name for f in dataclasses.fields(base)}
        bad = sorted(set(overrides) - known)
        if bad:
            raise ElicitError(f"task '{name}' has no setting(s) {', '.join(bad)}")
        config = dataclasses.replace(base, **overrides)
    return _make_cached(name, config)
