"""Scripted operators of ``reach-pillar``: around the left, around the right, or over the top.

The base operator passes the pillar on its left (+y). ``same-style`` does the same with its
own noise; ``mild`` takes a wider, slower left arc with pauses. The conflicting styles differ
from the base at its initial states, which every operator shares (see ``docs/operators.md``):
``conflict-right`` passes on the right and ``conflict-over`` climbs over the top — a
difference of direction from the first step, after which the state tells the styles apart;
``conflict-right-pause`` (the quickstart's conflicting D_new) first holds still for 40 control
steps where the base sets off at once, then passes on the right. Naive BC on the base's and
its demos creeps from the start and often runs out of the 100-step horizon
(``benchmarks/results/phenomenon-reach-pillar.md``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from elicit_jax.sim.operators.base import Operator, Style, Targets, reached
from elicit_jax.sim.tasks.reach_pillar import PILLAR_HEIGHT

DEFAULT_CHOICES = {"route": "left", "clearance": 0.09}
"""What a style that sets no choice does: the base operator's choices (a study measures a
person's distance from them; people never read them)."""


def _choice(style: Style, key: str) -> Any:
    """The style's choice ``key``, or the default (read only when the style has none)."""
    own = dict(style.choices)
    return own[key] if key in own else DEFAULT_CHOICES[key]


class ReachPillarOperator(Operator):
    """Three waypoints: beside (or above) the pillar's near side, its far side, the goal."""

    n_phases = 3

    def targets(self, obs: np.ndarray) -> Targets:
        self.pause_at_phase_starts()
        route = _choice(self.style, "route")
        clear = _choice(self.style, "clearance")
        eef, goal = obs[:, 0:3], obs[:, 9:12]
        b = len(obs)
        if route == "over":
            z = np.full(b, PILLAR_HEIGHT + clear * 0.6)
            near = np.stack([self.start_obs[:, 0], self.start_obs[:, 1], z], axis=1)
            far = np.stack([goal[:, 0], goal[:, 1], z], axis=1)
        else:
            y = np.full(b, clear if route == "left" else -clear)
            near = np.stack([np.full(b, -0.05), y, self.start_obs[:, 2]], axis=1)
            far = np.stack([np.full(b, 0.06), y, goal[:, 2]], axis=1)
        near = near + self.jitter
        tol = self.style.tol * 2
        phase = self.phase[:, None]
        pos = np.where(phase == 0, near, np.where(phase == 1, far, goal))
        done = np.where(
            self.phase == 0,
            reached(eef, near, tol),
            np.where(self.phase == 1, reached(eef, far, tol), False),
        )
        return Targets(pos=pos, yaw=np.zeros(b), grip=-np.ones(b), done=done)


RIGHT = Style(noise=0.03, choices=(("route", "right"),))
"""Passes the pillar on the right (``conflict-right``, and ``conflict-right-pause``)."""

STYLES: dict[str, tuple[Style, str]] = {
    "base": (Style(noise=0.03), "proficient; passes the pillar on the left"),
    "same-style": (
        Style(noise=0.06, speed=0.9, jitter=0.005),
        "compatible: the base route, noisier and a little slower",
    ),
    "mild": (
        Style(noise=0.05, speed=0.75, hesitate_prob=0.03, choices=(("clearance", 0.12),)),
        "mildly different: wider left arc, slower, hesitates",
    ),
    "conflict-right": (RIGHT, "conflicting: passes the pillar on the right"),
    "conflict-right-pause": (
        RIGHT.paused((0,), 40),
        "conflicting: holds still at the start where the base moves, then passes on the right",
    ),
    "conflict-over": (
        Style(noise=0.03, choices=(("route", "over"),)),
        "conflicting: climbs over the pillar",
    ),
}
OPERATOR_CLASS = ReachPillarOperator
