"""``round-nut``: pick a round nut by its handle and drop it over a round peg.

The nut is an octagonal ring of eight capsules with a capsule handle; the peg is a vertical
capsule (MJX has no cylinder collisions). Contacts are explicit pairs: nut-floor (9),
ring-peg (8), fingers-handle (2). The handle, initial poses, success and observations follow
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
    ring_sides = 8
    nut_rgba = "0.6 0.6 0.65 1"

    def peg_xml(self) -> str:
        """A capsule peg (its rounded top at ``PEG_HEIGHT``)."""
        return mjcf.vertical_capsule(
            "peg", PEG_XY, PEG_HEIGHT - PEG_RADIUS, PEG_RADIUS, "0.5 0.3 0.1 1"
        )

    def ring_xml(self) -> str:
        """The octagonal ring's eight capsules."""
        return octagon_geoms("ring", RING_MID, RING_RADIUS, 0.0125)
