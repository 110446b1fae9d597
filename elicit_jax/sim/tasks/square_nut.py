"""``square-nut``: pick a square nut by its handle and drop it over a square peg.

The nut is a ring of four capsules with a capsule handle (MJX has no cylinder-box or mesh
collisions, and capsules keep the contact cost low); the peg is a box. Contacts are explicit
pairs: nut-floor (5), ring-peg (4), fingers-handle (2). Fingers do not
collide with the peg or the floor (the end effector cannot go below ``z_min``). Success, like
robosuite: the nut's centre within ``xy_tol`` of the peg's axis, the nut low (resting around
the peg, not on top of it), the gripper open.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from elicit_jax.sim import mjcf
from elicit_jax.sim.env import ObjectTaskConfig, Task

PEG_XY = (0.1, 0.1)
PEG_HALF = 0.011
PEG_HEIGHT = 0.1
RING_HALF = 0.032
"""Distance from the nut's centre to the axis of each ring side."""
RING_RADIUS = 0.007
HANDLE_FROM, HANDLE_TO = 0.039, 0.097
NUT_Z = RING_RADIUS


@dataclasses.dataclass(frozen=True)
class SquareNutConfig(ObjectTaskConfig):
    """Square-nut settings.

    Attributes:
      nut_x, nut_y, nut_yaw: ranges (low, high) of the nut's initial pose.
      xy_tol: success distance of the nut's centre from the peg's axis.
      z_tol: the nut must be below this height (resting on the floor around the peg).
      open_tol: both finger positions above this count as released.
    """

    horizon: int = 500
    nut_x: tuple[float, float] = (-0.13, -0.07)
    nut_y: tuple[float, float] = (-0.12, -0.04)
    nut_yaw: tuple[float, float] = (-0.6, 0.6)
    xy_tol: float = 0.03
    z_tol: float = 0.03
    open_tol: float = 0.02


def ring_geoms(prefix: str, half: float, radius: float, mass: float) -> str:
    """Four capsules forming a square ring of side axes at distance ``half`` from the centre."""
    e = half + radius
    sides = (
        (-half, -e, -half, e),
        (half, -e, half, e),
        (-e, -half, e, -half),
        (-e, half, e, half),
    )
    return "\n".join(
        f'      <geom name="{prefix}{i}" type="capsule" fromto="{x0} {y0} 0 {x1} {y1} 0" '
        f'size="{radius}" mass="{mass}" rgba="0.7 0.6 0.1 1"/>'
        for i, (x0, y0, x1, y1) in enumerate(sides)
    )


class SquareNut(Task):
    """Square nut onto a square peg (see the module docstring)."""

    name = "square-nut"
    config_cls = SquareNutConfig
    peg_xy = PEG_XY
    peg_height = PEG_HEIGHT
    nut_z = NUT_Z
    ring_sides = 4
    nut_rgba = "0.7 0.6 0.1 1"

    def peg_xml(self) -> str:
        """The peg's MJCF (a geom named ``peg``)."""
        px, py = PEG_XY
        return f"""
    <body name="peg" pos="{px} {py} {PEG_HEIGHT / 2}">
      <geom name="peg" type="box" size="{PEG_HALF} {PEG_HALF} {PEG_HEIGHT / 2}"
            rgba="0.5 0.3 0.1 1"/>
    </body>"""

    def ring_xml(self) -> str:
        """The nut ring's ``ring_sides`` geoms, ``ring0`` ...; the handle is added by
        :meth:`xml`."""
        return ring_geoms("ring", RING_HALF, RING_RADIUS, 0.025)

    def xml(self) -> str:
        world = f"""{self.peg_xml()}
    <body name="nut" pos="-0.1 -0.08 {self.nut_z}">
      <freejoint name="nut"/>
      <site name="nut" size="0.004"/>
{self.ring_xml()}
      <geom name="handle" type="capsule" fromto="{HANDLE_FROM} 0 0 {HANDLE_TO} 0 0"
            size="{RING_RADIUS}" mass="0.03" rgba="{self.nut_rgba}"/>
    </body>"""
        ring = [f"ring{i}" for i in range(self.ring_sides)]
        pairs = [("floor", g) for g in ring] + [("floor", "handle")]
        pairs += [("peg", g) for g in ring]
        pairs += [(f, "handle") for f in mjcf.FINGER_JOINTS]
        return mjcf.scene(
            self.name, self.config.timestep, world, mjcf.pairs(pairs), mjcf.pose_sensors("nut")
        )

    def sample_init(self, rng: Any) -> tuple[Any, Any]:
        import jax.numpy as jnp

        c = self.config
        qpos = self.gripper_and_object_qpos(rng, c.nut_x, c.nut_y, c.nut_yaw, self.nut_z)
        return qpos, jnp.zeros((0, 3))

    def success_from_obs(self, obs: Any, xp: Any = np) -> Any:
        c = self.config
        dx = obs[..., 9] - self.peg_xy[0]
        dy = obs[..., 10] - self.peg_xy[1]
        centred = dx * dx + dy * dy < c.xy_tol**2
        low = obs[..., 11] < c.z_tol
        released = xp.min(obs[..., 7:9], axis=-1) > c.open_tol
        return centred & low & released
