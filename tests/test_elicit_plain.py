"""Feedback in plain words from the geometry, per-window retrieval, the person horizon."""

from __future__ import annotations

import numpy as np
import pytest

from elicit_jax.compat.feedback import retrieve
from elicit_jax.elicit.config import person_horizon
from elicit_jax.elicit.plain import (
    gripper_sentence,
    nut_sentences,
    offset_sentence,
    pillar_side,
    plain_words,
)
from elicit_jax.sim.env import OBS_FIELDS

PILLAR = ((0.0, 0.0), 0.14)


def states(xyz, fingers=0.04, rel_yaw=0.0, nut_yaw=0.0):
    """(T, 23) states of the simulated layout with the gripper at ``xyz`` (T, 3)."""
    xyz = np.asarray(xyz, np.float64)
    s = np.zeros((len(xyz), 23))
    s[:, 0:3] = xyz
    s[:, 3] = 1.0
    s[:, 7:9] = fingers
    s[:, 12], s[:, 15] = np.cos(nut_yaw / 2), np.sin(nut_yaw / 2)
    s[:, 19], s[:, 22] = np.cos(rel_yaw / 2), np.sin(rel_yaw / 2)
    return s


def route(y, z=0.06, n=21):
    """A straight path from x = -0.2 to x = 0.2 at height ``z`` and side ``y``."""
    x = np.linspace(-0.2, 0.2, n)
    return np.stack([x, np.full(n, y), np.full(n, z)], axis=1)


def test_pillar_side_at_the_crossing():
    assert pillar_side(states(route(-0.05)), *PILLAR) == "right"  # -y is the right
    assert pillar_side(states(route(0.05)), *PILLAR) == "left"
    assert pillar_side(states(route(-0.05, z=0.2)), *PILLAR) == "over"
    assert pillar_side(states(route(0.05)[:5]), *PILLAR) == ""  # never reaches x = 0


def test_reach_pillar_says_which_side_in_plain_words():
    op, base = states(route(-0.05)), states(route(0.06))
    words = plain_words("reach-pillar", OBS_FIELDS, op[8:13], base[8:13], op, base)
    assert words == ("you went right of the pillar; the base goes left of it",)
    over = states(route(0.0, z=0.2))
    words = plain_words("reach-pillar", OBS_FIELDS, over[:5], base[:5], over, base)
    assert words[0] == "you went over the pillar; the base goes left of it"
    # the same side: no route sentence, an offset instead (4 cm lower, with the key)
    low = states(route(0.06, z=0.02))
    words = plain_words("reach-pillar", OBS_FIELDS, low[:5], base[:5], low, base)
    assert words == ("your gripper is 4 cm lower than the base's here (keys R)",)


def test_offsets_gripper_and_motion_by_hand():
    op = states(np.tile([0.03, -0.025, 0.1], (4, 1)))
    base = states(np.tile([0.0, 0.0, 0.1], (4, 1)))
    assert offset_sentence(op, base) == (
        "your gripper is 3 cm further forward and 2 cm further right than the base's here "
        "(keys S, A)"
    )
    assert offset_sentence(base, base) == ""
    closed = states(np.zeros((4, 3)), fingers=0.0)
    assert (
        gripper_sentence(closed, base) == "you close the gripper where the base keeps it open (G)"
    )
    assert (
        gripper_sentence(base, closed)
        == "you keep the gripper open where the base has closed it (G)"
    )
    # the simulated layout's motion is read from the gripper, not from the motion argument
    assert plain_words("hammer-drawer", OBS_FIELDS, base, base, base, base, motion="still") == ()
    moving = states(route(0.0, z=0.1, n=4))  # 13 cm a step along x, centred on base
    (still,) = plain_words("hammer-drawer", OBS_FIELDS, base, moving, base, moving)
    assert still.startswith("you hold still where the base moves (your gripper still in 3 of 3")


def test_nut_wrist_turned_and_grasp_point():
    # the nut's yaw in the gripper's frame half a turn from the base's: the other way round
    op = states(np.zeros((4, 3)), rel_yaw=np.pi - 0.1)
    base = states(np.zeros((4, 3)), rel_yaw=0.0)
    (line,) = nut_sentences(op, base, (0.039, 0.097))
    assert line.startswith("your wrist is turned about 170° from the base's against the nut")
    # both closed on the handle (nut at the origin, turned 90°: the handle along +y)
    near_end = states(np.tile([0.0, 0.09, 0.01], (4, 1)), fingers=0.0, nut_yaw=np.pi / 2)
    near_ring = states(np.tile([0.0, 0.05, 0.01], (4, 1)), fingers=0.0, nut_yaw=np.pi / 2)
    assert nut_sentences(near_end, near_ring, (0.039, 0.097)) == [
        "you hold the handle 4 cm nearer the handle's end than the base"
    ]
    ring = states(np.tile([0.0, 0.0, 0.01], (4, 1)), fingers=0.0, nut_yaw=np.pi / 2)
    assert nut_sentences(ring, near_ring, (0.039, 0.097)) == [
        "you hold the nut by its ring; the base holds it by the handle"
    ]


@pytest.mark.parametrize("method", ["l2", "dtw"])
def test_each_window_gets_its_own_base_segment(method):
    # one base demo moving 0..29 along x; two identical windows match steps 10-14 best
    base = [np.stack([np.arange(30.0), np.zeros(30)], axis=1)]
    win = np.stack([np.arange(10.0, 15.0), np.zeros(5)], axis=1)
    stats = (np.zeros(2), np.ones(2))
    first, second = retrieve([win, win], base, method, stats)
    assert (first.start, first.stop) == (10, 15) and first.distance == 0.0
    assert second.stop <= 10 or second.start >= 15  # its own segment, not the first's
    assert second.distance > 0
    same = retrieve([win, win], base, method, stats, distinct=False)
    assert (same[1].start, same[1].stop) == (same[0].start, same[0].stop)


def test_person_horizon_from_base_lengths():
    lengths = [38, 38, 39, 40, 40, 41, 42, 43, 43, 45]
    p95 = np.percentile(lengths, 95)  # 44.1 -> 4 x = 176.4 -> 180 (a multiple of 20)
    assert p95 == pytest.approx(44.1)
    assert person_horizon(100, lengths) == 180
    assert person_horizon(500, lengths) == 500  # never shorter than the task's
    assert person_horizon(100, []) == 100
