"""Scripted operators on C MuJoCo: proficiency, and styles that differ as designed."""

import numpy as np
import pytest

from elicit_jax.errors import ElicitError
from elicit_jax.sim.collect import operator_rng, run_batch
from elicit_jax.sim.env import make_task, quat_yaw
from elicit_jax.sim.operators import make_operator, operator_names
from elicit_jax.sim.operators.square_nut import STYLES
from elicit_jax.sim.rollout_mujoco import BatchSim

SEEDS = np.arange(100, 120)


def _run(task_name, op_name, seeds=SEEDS, record=None):
    task = make_task(task_name)
    op = make_operator(task, op_name)
    with BatchSim(task, len(seeds)) as sim:
        out = run_batch(task, op, sim, seeds, operator_rng(0, op_name))
    return out


@pytest.fixture(scope="module")
def nut_runs():
    return {op: _run("square-nut", op) for op in operator_names("square-nut")}


@pytest.fixture(scope="module")
def reach_runs():
    return {op: _run("reach-pillar", op) for op in operator_names("reach-pillar")}


def test_registry():
    names = operator_names("square-nut")
    assert {
        "base",
        "same-style",
        "mild",
        "conflict-flip",
        "conflict-flip-tip",
        "conflict-flip-pause",
    } <= set(names)
    assert len(operator_names("reach-pillar")) >= 5
    with pytest.raises(ElicitError, match="has no operator 'nobody'"):
        make_operator(make_task("square-nut"), "nobody")


def test_every_operator_is_proficient(nut_runs, reach_runs):
    for runs in (nut_runs, reach_runs):
        for op, out in runs.items():
            assert out["success"].mean() >= 0.9, (op, out["success"].mean())
    assert nut_runs["base"]["success"].all() and reach_runs["base"]["success"].all()


def test_actions_in_bounds(nut_runs):
    for out in nut_runs.values():
        assert np.abs(out["action"]).max() <= 1.0


def _grasp_yaw(out):
    """Wrist yaw at the first step the gripper command turns to close."""
    yaws = []
    for obs, act in zip(out["obs"], out["action"], strict=True):
        t = int(np.argmax(act[:, 6] > 0))
        yaws.append(quat_yaw(obs[t, 3:7]) - quat_yaw(obs[t, 12:16]))
    return np.angle(np.exp(1j * np.asarray(yaws)))


def test_square_nut_grasp_yaw_conflicts(nut_runs):
    base = _grasp_yaw(nut_runs["base"])
    assert np.abs(base).max() < 0.15  # base: wrist aligned with the nut
    assert np.abs(_grasp_yaw(nut_runs["same-style"])).max() < 0.15  # compatible
    for op in ("conflict-flip", "conflict-flip-tip", "conflict-flip-pause"):
        flipped = np.abs(_grasp_yaw(nut_runs[op]))
        assert np.mean(flipped > np.pi - 0.25) >= 0.9, op  # half a turn away from the base


def test_square_nut_conflicting_actions_differ_at_the_same_states(nut_runs):
    """From the same initial observation, the first wrist command of the base and of a
    conflicting operator have opposite signs whenever the nut is turned noticeably."""
    b0 = nut_runs["base"]
    c0 = nut_runs["conflict-flip"]
    np.testing.assert_array_equal(b0["obs"][:, 0], c0["obs"][:, 0])  # same initial states
    nut_yaw = quat_yaw(b0["obs"][:, 0, 12:16])
    turned = np.abs(nut_yaw) > 0.2
    assert turned.sum() >= 5
    base_turn = b0["action"][turned, 0, 5]
    conflict_turn = c0["action"][turned, 0, 5]
    assert np.all(np.sign(base_turn) != np.sign(conflict_turn))
    assert np.abs(conflict_turn).min() > 0.8  # the conflicting wrist turns at full speed


def test_mild_slides_in_from_the_tip(nut_runs):
    """'mild' descends beside the handle's tip (down-then-across): its lowest approach point
    before closing is farther from the nut than the base's grasp point."""

    def descent_dist(out):
        d = []
        for obs, act in zip(out["obs"], out["action"], strict=True):
            t_close = int(np.argmax(act[:, 6] > 0))
            low = np.flatnonzero(obs[:t_close, 2] < 0.03)
            d.append(np.linalg.norm(obs[low[0], 0:2] - obs[low[0], 9:11]))
        return np.median(d)

    assert descent_dist(nut_runs["mild"]) > descent_dist(nut_runs["base"]) + 0.03


def test_reach_pillar_routes(reach_runs):
    """Where the gripper passes the pillar (x = 0): base and same-style on +y, conflict-right
    on -y, conflict-over above the pillar's top."""

    def at_pillar(out):
        rows = []
        for obs, n in zip(out["obs"], out["length"], strict=True):
            t = int(np.argmin(np.abs(obs[:n, 0])))
            rows.append(obs[t, 0:3])
        return np.array(rows)

    assert (at_pillar(reach_runs["base"])[:, 1] > 0.05).all()
    assert (at_pillar(reach_runs["same-style"])[:, 1] > 0.05).all()
    assert (at_pillar(reach_runs["conflict-right"])[:, 1] < -0.05).all()
    assert (at_pillar(reach_runs["conflict-right-pause"])[:, 1] < -0.05).all()
    assert (at_pillar(reach_runs["conflict-over"])[:, 2] > 0.14).all()


def test_round_nut_base_and_conflict_are_proficient():
    for op in ("base", "same-style", "conflict-flip", "conflict-flip-pause"):
        out = _run("round-nut", op, seeds=np.arange(10))
        assert out["success"].mean() >= 0.9, op


def _assert_pauses_where_the_base_moves(base, pause, n: int) -> None:
    """From the same initial observations the base moves at once (translation > 0.5), while
    the pausing style holds still (zero translation and rotation) for its first ``n`` steps,
    then moves."""
    np.testing.assert_array_equal(base["obs"][:, 0], pause["obs"][:, 0])
    assert np.abs(base["action"][:, 0, 0:3]).max(axis=1).min() > 0.5
    assert np.abs(pause["action"][:, :n, 0:6]).max() == 0.0
    assert np.abs(pause["action"][:, n, 0:3]).max(axis=1).min() > 0.5


def test_square_nut_pause_holds_still_where_the_base_moves(nut_runs):
    """From the same initial observations the base moves at once, while 'conflict-flip-pause'
    holds still for its first ``pause_steps`` control steps (same states, zero action: the
    naive mean action there is ~0), and again above the handle and above the peg."""
    n = dict(STYLES["conflict-flip-pause"][0].choices)["pause_steps"]
    b0, p0 = nut_runs["base"], nut_runs["conflict-flip-pause"]
    _assert_pauses_where_the_base_moves(b0, p0, n)
    still = (np.abs(p0["action"][:, :, 0:6]).max(axis=2) == 0.0).sum(axis=1)
    assert (still >= 3 * n).all(), still.min()  # start, above the handle, above the peg


def test_reach_pillar_pause_holds_still_at_the_start(reach_runs):
    """'conflict-right-pause' starts from the base's initial states and holds still for its
    pause where the base moves at once, then moves."""
    from elicit_jax.sim.operators.reach_pillar import STYLES as REACH

    n = dict(REACH["conflict-right-pause"][0].choices)["pause_steps"]
    b0, p0 = reach_runs["base"], reach_runs["conflict-right-pause"]
    _assert_pauses_where_the_base_moves(b0, p0, n)
    assert (p0["length"] < reach_runs["base"]["length"] + n + 10).all()
