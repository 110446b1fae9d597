"""``round-nut``: pick a round nut by its handle and drop it over a round peg.

The nut is an octagonal ring of eight capsules with a capsule handle; the peg is a vertical
capsule (MJX has no cylinder collisions). Contacts are explicit pairs: nut-floor (9),
ring-peg (8), fingers-handle (2). Initial poses, success and observations follow
``square-nut`` (see :mod:`elicit_jax.sim.tasks.square_nut`), with the peg elsewhere.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

from elicit_jax.sim import mjcf
from elicit_jax.sim.tasks.square_nut import SquareNut, SquareNutConfig

PEG_XY = (0.12, 0.06)
PEG_RADIUS = 0.012
PEG_HEIGHT = 0.1
RING_RADIUS = 0.007
RING_MID = 0.032
"""Distance from the nut's centre to the midpoint of each ring side."""
HANDLE_FROM, HANDLE_TO = 0.039, 0.097


@dataclasses.dataclass(frozen=True)
class RoundNutConfig(SquareNutConfig):
    """Round-nut settings (the square nut's, with the paper's horizon of 400)."""

    horizon: int = 400


def octagon_geoms(prefix: str, mid: float, radius: float, mass: float) -> str:
    """Eight capsules along a regular octagon whose sides' midpoints are ``mid`` away."""
    r = mid / math.cos(math.pi / 8)
    pts = [
        (r * math.cos(math.pi / 8 + k * math.pi / 4), r * math.sin(math.pi / 8 + k * math.pi / 4))
        for k in range(9)
    ]
    return "\n".join(
        f'      <geom name="{prefix}{k}" type="capsule" fromto="{x0:.5f} {y0:.5f} 0 {x1:.5f} '
        f'{y1:.5f} 0" size="{radius}" mass="{mass}" rgba="0.6 0.6 0.65 1"/>'
        for k, ((x0, y0), (x1, y1)) in enumerate(itertools.pairwise(pts))
    )


class RoundNut(SquareNut):
    """Round nut onto a round peg (see the module docstring)."""

    name = "round-nut"
    config_cls = RoundNutConfig
    peg_xy = PEG_XY
    peg_height = PEG_HEIGHT
    nut_z = RING_RADIUS

    def xml(self) -> str:
        px, py = PEG_XY
        world = f"""
    <geom name="peg" type="capsule" fromto="{px} {py} 0 {px} {py} {PEG_HEIGHT - PEG_RADIUS}"
          size="{PEG_RADIUS}" rgba="0.5 0.3 0.1 1"/>
    <body name="nut" pos="-0.1 -0.08 {RING_RADIUS}">
      <freejoint name="nut"/>
      <site name="nut" size="0.004"/>
{octagon_geoms("ring", RING_MID, RING_RADIUS, 0.0125)}
      <geom name="handle" type="capsule" fromto="{HANDLE_FROM} 0 0 {HANDLE_TO} 0 0"
            size="{RING_RADIUS}" mass="0.03" rgba="0.6 0.6 0.65 1"/>
    </body>"""
        pairs = [("floor", f"ring{i}") for i in range(8)] + [("floor", "handle")]
        pairs += [("peg", f"ring{i}") for i in range(8)]
        pairs += [(f, "handle") for f in mjcf.FINGER_JOINTS]
        return mjcf.scene(
            self.name, self.config.timestep, world, mjcf.pairs(pairs), mjcf.pose_sensors("nut")
        )
