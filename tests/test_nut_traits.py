"""Per-episode traits of robosuite nut demos, measured from their own states (no robosuite
needed): hand-built episodes whose grasp side, approach and start are known by construction."""

import numpy as np
import pytest

from elicit_jax.sim.operators.nut_traits import LOW_HEIGHT, measure


def _quat_z(yaw: np.ndarray) -> np.ndarray:
    """(T, 4) x-y-z-w quaternions of a pure turn ``yaw (T,)`` about z."""
    return np.stack([np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2), np.cos(yaw / 2)], 1)


def _episode(path: np.ndarray, yaw: np.ndarray, nut_yaw: float, close_at: int, still: int = 0):
    """obs (T, 23) along an end-effector ``path (T, 3)`` with wrist ``yaw (T,)``, a nut resting
    at the table-plane origin (at the grasp height) with yaw ``nut_yaw``; actions close the
    jaw from ``close_at`` on and hold still for the first ``still`` steps."""
    t = len(path)
    obs = np.zeros((t, 23))
    obs[:, 0:3], obs[:, 3:7] = path, _quat_z(yaw)
    obs[:, 16:19] = [0.0, 0.0, GRASP[2]]
    obs[:, 19:23] = _quat_z(np.full(t, nut_yaw))
    action = np.zeros((t, 7))
    action[still:, 0] = 0.5
    action[:, 6] = np.where(np.arange(t) >= close_at, 1.0, -1.0)
    return obs, action


def _line(a, b, n):
    return np.linspace(a, b, n)


GRASP = np.array([0.05, 0.0, 0.83])
START = np.array([0.05, 0.20, 1.00])


def test_across_then_down_with_the_near_turn_does_not_conflict():
    hover = GRASP + np.array([0, 0, 0.06])
    path = np.concatenate([_line(START, hover, 20), _line(hover, GRASP, 10)])
    obs, action = _episode(path, _line(0.0, 0.4, 30), nut_yaw=0.4, close_at=29)
    t = measure(obs, action)
    assert (t.grasp_step, t.far_grasp, t.down_first, t.slide_in) == (29, False, False, False)
    assert t.low_share == pytest.approx(0.0)
    assert t.near_turn == pytest.approx(0.4)
    assert t.approach_height == pytest.approx(0.06, abs=0.01)
    assert not t.conflicts


def test_down_then_across_conflicts_in_any_state():
    low = np.array([START[0], START[1], GRASP[2] + 0.03])
    path = np.concatenate([_line(START, low, 10), _line(low, GRASP + np.array([0, 0, 0.03]), 15),
                           _line(GRASP + np.array([0, 0, 0.03]), GRASP, 5)])  # fmt: skip
    obs, action = _episode(path, np.zeros(30), nut_yaw=0.0, close_at=29, still=4)
    t = measure(obs, action)
    assert t.down_first and t.conflicts and not t.far_grasp
    assert t.still_start == 4
    # all the way across 3 cm above the grasp height: under the threshold (the base's is 6)
    assert 0.03 < LOW_HEIGHT < 0.06 and t.low_share == pytest.approx(1.0)


def test_the_far_grasp_is_the_half_turn_from_the_near_one():
    hover = GRASP + np.array([0, 0, 0.06])
    path = np.concatenate([_line(START, hover, 20), _line(hover, GRASP, 10)])
    # near side: +0.4 rad; this demo turned the other way round, to 0.4 - pi
    obs, action = _episode(path, _line(0.0, 0.4 - np.pi, 30), nut_yaw=0.4, close_at=29)
    t = measure(obs, action)
    assert t.far_grasp and t.conflicts and not t.down_first
    assert t.grasp_turn == pytest.approx(0.4 - np.pi, abs=1e-6)


def test_a_nut_nudged_under_the_closing_jaw_does_not_make_the_base_look_low():
    """The base's way, but the nut is pushed 3 cm while the jaw comes down over it: read in
    the table frame the last 3 cm look like a low way across; in the nut's frame they are not
    (the case that made a real base demo read as 'down first')."""
    hover = GRASP + np.array([0, 0, 0.06])
    path = np.concatenate(
        [_line(START, hover, 20), _line(hover, GRASP, 5), np.tile(GRASP, (10, 1))]
    )
    obs, action = _episode(path, np.zeros(35), nut_yaw=0.0, close_at=34)
    obs[25:, 0:2] += _line(np.zeros(2), np.array([0.0, 0.03]), 10)  # jaw and nut pushed along
    obs[25:, 16:18] += _line(np.zeros(2), np.array([0.0, 0.03]), 10)
    t = measure(obs, action)
    assert t.low_share < 0.2 and not t.down_first and not t.conflicts


def test_a_demo_whose_jaw_never_closes_measures_no_grasp():
    path = _line(START, GRASP, 10)
    obs, action = _episode(path, np.zeros(10), nut_yaw=0.0, close_at=99)
    t = measure(obs, action)
    assert t.grasp_step == -1 and not t.conflicts and np.isnan(t.approach_height)
