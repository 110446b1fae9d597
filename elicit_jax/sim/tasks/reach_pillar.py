"""``reach-pillar``: bring the end effector to a goal behind a pillar, over or around it.

A small, fast task for tests and the quickstart: one capsule pillar between the gripper's
start and a randomised goal (a mocap site), three contact pairs (palm and fingers against the
pillar). Success: the end effector within ``goal_tol`` of the goal.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import numpy as np

from elicit_jax.sim import mjcf
from elicit_jax.sim.env import Task, TaskConfig

PILLAR_XY = (0.0, 0.0)
PILLAR_RADIUS = 0.03
PILLAR_HEIGHT = 0.14


@dataclasses.dataclass(frozen=True)
class ReachPillarConfig(TaskConfig):
    """Reach-pillar settings.

    Attributes:
      start_x, start_y, start_z: ranges (low, high) of the gripper's start position.
      goal_x, goal_y, goal_z: ranges of the goal position.
      goal_tol: success distance (m).
    """

    horizon: int = 100
    start_x: tuple[float, float] = (-0.19, -0.15)
    start_y: tuple[float, float] = (-0.04, 0.04)
    start_z: tuple[float, float] = (0.05, 0.08)
    goal_x: tuple[float, float] = (0.15, 0.19)
    goal_y: tuple[float, float] = (-0.04, 0.04)
    goal_z: tuple[float, float] = (0.05, 0.08)
    goal_tol: float = 0.02


class ReachPillar(Task):
    """Reach a goal past a pillar (see the module docstring)."""

    name = "reach-pillar"
    config_cls = ReachPillarConfig
    scene_hints: ClassVar[dict[str, Any]] = {
        # the browser's camera starts beside the route, not behind its start: the pillar
        # stands between start (left) and goal (right), and the final approach to the goal
        # is in plain sight instead of behind the pillar
        "home": {"position": (0.02, -0.6, 0.36), "target": (0.0, 0.0, 0.05)},
    }

    def xml(self) -> str:
        pillar = mjcf.vertical_capsule(
            "pillar", PILLAR_XY, PILLAR_HEIGHT, PILLAR_RADIUS, "0.6 0.4 0.2 1"
        )
        world = f"""{pillar}
    <body name="goal" mocap="true" pos="0.17 0 0.06">
      <site name="goal" size="0.012" rgba="0 0.8 0 0.5"/>
    </body>"""
        contact = mjcf.pairs([("pillar", "palm"), ("pillar", "finger_l"), ("pillar", "finger_r")])
        return mjcf.scene(
            self.name, self.config.timestep, world, contact, mjcf.pose_sensors("goal")
        )

    def sample_init(self, rng: Any) -> tuple[Any, Any]:
        import jax
        import jax.numpy as jnp

        c = self.config
        lo = jnp.array([c.start_x[0], c.start_y[0], c.start_z[0], c.goal_x[0], c.goal_y[0]])
        hi = jnp.array([c.start_x[1], c.start_y[1], c.start_z[1], c.goal_x[1], c.goal_y[1]])
        k1, k2 = jax.random.split(rng)
        u = jax.random.uniform(k1, (5,), minval=lo, maxval=hi)
        gz = jax.random.uniform(k2, (), minval=c.goal_z[0], maxval=c.goal_z[1])
        qpos = jnp.asarray(self.qpos0).at[0:3].set(u[0:3]).at[4:6].set(mjcf.FINGER_OPEN)
        mocap = jnp.stack([u[3], u[4], gz])[None, :]
        return qpos, mocap

    def success_from_obs(self, obs: Any, xp: Any = np) -> Any:
        dist = xp.sqrt(xp.sum((obs[..., 0:3] - obs[..., 9:12]) ** 2, axis=-1))
        return dist < self.config.goal_tol
