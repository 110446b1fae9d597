"""``hammer-drawer``: open a drawer by its handle, put a hammer inside, push the drawer shut.

Scene (metres, world frame; the gripper starts near the origin): a cabinet at +x whose drawer
slides out towards -x on a slide joint (``drawer``, 0 closed, up to ``SLIDE_MAX`` open). The
drawer is a box tray: a solid bottom, four walls and a bar handle (a capsule along y) standing
off its front, with room between bar and front for the closed jaw to hook behind it. The
cabinet's top is solid (the hammer cannot be dropped into a closed drawer); its sides are
visual. The hammer is a free body of two capsules (handle along its local x, head across it at
+x; MJX has no cylinder-box or mesh collisions) lying on the floor to the front-left (-y).

Contacts are twelve explicit pairs: hammer handle and head with the floor, the drawer's bottom
and the cabinet top (6); the head with the drawer's front and back walls (2), so a hammer
placed along the drawer's short side (x) rests on a wall instead of inside; both fingers with
the hammer's handle and with the drawer's handle bar (4).

Observation: the 23-D layout of every task (see :mod:`elicit_jax.sim.env`), with the 14-D
``object`` block filled as: hammer position (3) and quaternion (4) in the world, hammer
position in the end-effector frame (3), drawer-handle position in the end-effector frame (3),
drawer opening (1, metres, 0 closed). The hammer's orientation relative to the jaw, which the
other tasks put in the last four values, is redundant here (the jaw only yaws, and both
quaternions are observed), so its place holds the drawer's state. All values are MuJoCo
sensors, computed identically by both simulators.

Success (robosuite-like): the hammer's centre (its body origin) inside the drawer's interior
box (x, y within the walls; z between the drawer's floor and the top of its walls) and the
drawer closed (opening below ``closed_tol``). The gripper need not release the hammer: the
check reads only the hammer and the drawer (the scripted operators let go before closing).

Initial states: the drawer closed, the hammer's position and yaw uniform in the config's
ranges, the gripper's start jittered in xy; drawn from the PRNG key by :meth:`sample_init`,
the same JAX sampler for both backends. Horizon 175 control steps (the paper's), with the
action scales raised to 0.04 m and 0.25 rad per control step (other tasks: 0.02 m, 0.15 rad):
the scripted base operator walks 15 phases over about 1.4 m of gripper travel and a quarter
turn of the wrist with the hammer in hand, which at the default scales took 175-200 steps
(its episodes now take about 130).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from elicit_jax.sim import mjcf
from elicit_jax.sim.env import ObjectTaskConfig, Task

INTERIOR_X = 0.2
"""x of the drawer interior's centre when closed."""
INTERIOR_HALF = (0.065, 0.1)
"""Half extents (x, y) of the drawer's interior."""
WALL = 0.005
"""Half thickness of the drawer's walls and bottom."""
FLOOR_Z = 0.03
"""Height of the drawer bottom's upper face (the drawer's floor)."""
WALL_TOP = 0.075
"""Height of the drawer walls' top."""
TOP_Z = 0.085
"""Height of the cabinet top's lower face."""
BAR_OFFSET = 0.048
"""Distance from the drawer front's outer face to the handle bar's axis."""
BAR_Z = 0.055
BAR_RADIUS = 0.008
BAR_HALF = 0.06
SLIDE_MAX = 0.16
HAMMER_Z = 0.014
"""Height of the hammer's origin when it lies on the floor."""
HANDLE_FROM, HANDLE_TO, HANDLE_RADIUS = -0.06, 0.045, 0.009
HEAD_X, HEAD_HALF, HEAD_RADIUS = 0.058, 0.032, 0.014

FRONT_X = INTERIOR_X - INTERIOR_HALF[0] - 2 * WALL
"""x of the drawer front's outer face when closed."""
BAR_X = FRONT_X - BAR_OFFSET
"""x of the handle bar's axis when closed."""


@dataclasses.dataclass(frozen=True)
class HammerDrawerConfig(ObjectTaskConfig):
    """Hammer-drawer settings.

    Attributes:
      hammer_x, hammer_y, hammer_yaw: ranges (low, high) of the hammer's initial pose.
      closed_tol: the drawer counts as closed below this opening (m).
    """

    horizon: int = 175
    pos_scale: float = 0.04
    rot_scale: float = 0.25
    hammer_x: tuple[float, float] = (-0.14, -0.06)
    hammer_y: tuple[float, float] = (-0.24, -0.18)
    hammer_yaw: tuple[float, float] = (-0.6, 0.6)
    closed_tol: float = 0.01


def _box(name: str, center: tuple[float, float, float], half: tuple[float, float, float],
         extra: str = "") -> str:  # fmt: skip
    c, h = " ".join(f"{v:.4f}" for v in center), " ".join(f"{v:.4f}" for v in half)
    return f'<geom name="{name}" type="box" pos="{c}" size="{h}" {extra}/>'


def drawer_body() -> str:
    """The drawer: bottom, walls and handle bar, on a slide joint opening towards -x."""
    hx, hy = INTERIOR_HALF
    wall_h = (WALL_TOP - FLOOR_Z) / 2
    wall_z = FLOOR_Z + wall_h
    wood = 'rgba="0.55 0.4 0.25 1"'
    parts = [
        _box("drawer_bottom", (0, 0, FLOOR_Z - WALL), (hx + 2 * WALL, hy + 2 * WALL, WALL),
             f'mass="0.2" {wood}'),
        _box("drawer_front", (-hx - WALL, 0, wall_z), (WALL, hy + 2 * WALL, wall_h),
             f'mass="0.05" {wood}'),
        _box("drawer_back", (hx + WALL, 0, wall_z), (WALL, hy + 2 * WALL, wall_h),
             f'mass="0.05" {wood}'),
        _box("drawer_left", (0, hy + WALL, wall_z), (hx, WALL, wall_h), f'mass="0.05" {wood}'),
        _box("drawer_right", (0, -hy - WALL, wall_z), (hx, WALL, wall_h), f'mass="0.05" {wood}'),
    ]  # fmt: skip
    bx, bz = -hx - 2 * WALL - BAR_OFFSET, BAR_Z
    for i, y in enumerate((-BAR_HALF + 0.01, BAR_HALF - 0.01)):
        parts.append(
            f'<geom name="bar_post{i}" type="capsule" fromto="{bx:.4f} {y} {bz} {-hx - WALL:.4f} '
            f'{y} {bz}" size="0.004" mass="0.005" rgba="0.3 0.3 0.3 1"/>'
        )
    geoms = "\n      ".join(parts)
    return f"""
    <body name="drawer" pos="{INTERIOR_X} 0 0">
      <joint name="drawer" type="slide" axis="-1 0 0" range="0 {SLIDE_MAX}" damping="8"/>
      {geoms}
      <geom name="drawer_handle" type="capsule" fromto="{bx:.4f} {-BAR_HALF} {bz} {bx:.4f}
            {BAR_HALF} {bz}" size="{BAR_RADIUS}" mass="0.02" rgba="0.3 0.3 0.3 1"/>
      <site name="drawer_handle" pos="{bx:.4f} 0 {bz}" size="0.004"/>
    </body>"""


def cabinet_geoms() -> str:
    """The cabinet around the closed drawer: a solid top, visual sides and back."""
    hx, hy = INTERIOR_HALF
    cx, half_x, half_y = INTERIOR_X + WALL, hx + 3 * WALL, hy + 4 * WALL
    side_h = (TOP_Z + 2 * WALL) / 2
    grey = 'rgba="0.7 0.7 0.72 1"'
    return "\n    ".join(
        [
            _box("cabinet_top", (cx, 0, TOP_Z + WALL), (half_x, half_y, WALL), grey),
            _box("cabinet_left", (cx, half_y + WALL, side_h), (half_x, WALL, side_h), grey),
            _box("cabinet_right", (cx, -half_y - WALL, side_h), (half_x, WALL, side_h), grey),
            _box("cabinet_back", (cx + half_x + WALL, 0, side_h), (WALL, half_y + 2 * WALL,
                 side_h), grey),
        ]
    )  # fmt: skip


def hammer_body() -> str:
    """The hammer: a handle capsule along local x and a head capsule across it at +x."""
    hz = HEAD_RADIUS - HANDLE_RADIUS
    return f"""
    <body name="hammer" pos="-0.1 -0.2 {HAMMER_Z}">
      <freejoint name="hammer"/>
      <site name="hammer" size="0.004"/>
      <geom name="hammer_handle" type="capsule" fromto="{HANDLE_FROM} 0 {-hz} {HANDLE_TO} 0
            {-hz}" size="{HANDLE_RADIUS}" mass="0.04" rgba="0.6 0.45 0.2 1"/>
      <geom name="hammer_head" type="capsule" fromto="{HEAD_X} {-HEAD_HALF} 0 {HEAD_X}
            {HEAD_HALF} 0" size="{HEAD_RADIUS}" mass="0.06" rgba="0.4 0.4 0.45 1"/>
    </body>"""


def sensors() -> str:
    """The 23 observation values (see the module docstring), in order."""
    more = (
        '    <framepos name="handle_rel_pos" objtype="site" objname="drawer_handle"'
        ' reftype="site"\n              refname="eef"/>\n'
        '    <jointpos name="drawer" joint="drawer"/>'
    )
    return mjcf.object_sensors("hammer", more)


class HammerDrawer(Task):
    """Open the drawer, put the hammer in, close it (see the module docstring)."""

    name = "hammer-drawer"
    config_cls = HammerDrawerConfig

    def xml(self) -> str:
        world = hammer_body() + drawer_body() + "\n    " + cabinet_geoms()
        hammer = ("hammer_handle", "hammer_head")
        pairs = [(g, h) for g in ("floor", "drawer_bottom", "cabinet_top") for h in hammer]
        pairs += [("drawer_front", "hammer_head"), ("drawer_back", "hammer_head")]
        pairs += [(f, g) for g in ("hammer_handle", "drawer_handle") for f in mjcf.FINGER_JOINTS]
        return mjcf.scene(self.name, self.config.timestep, world, mjcf.pairs(pairs), sensors())

    def sample_init(self, rng: Any) -> tuple[Any, Any]:
        import jax.numpy as jnp

        c = self.config
        qpos = self.gripper_and_object_qpos(rng, c.hammer_x, c.hammer_y, c.hammer_yaw, HAMMER_Z)
        qpos = qpos.at[13].set(0.0)
        return qpos, jnp.zeros((0, 3))

    def success_from_obs(self, obs: Any, xp: Any = np) -> Any:
        opening = obs[..., 22]
        dx = obs[..., 9] - (INTERIOR_X - opening)
        inside = (xp.abs(dx) < INTERIOR_HALF[0]) & (xp.abs(obs[..., 10]) < INTERIOR_HALF[1])
        inside &= (obs[..., 11] > FLOOR_Z) & (obs[..., 11] < WALL_TOP)
        return inside & (opening < self.config.closed_tol)
