"""Task definitions: purity and determinism, shared kernels, MJX against C MuJoCo."""

import numpy as np
import pytest

from elicit_jax.errors import ElicitError
from elicit_jax.sim.env import OBS_DIM, make_task, quat_yaw, task_names, yaw_quat
from elicit_jax.sim.rollout_mujoco import BatchSim


def test_registry_and_errors():
    assert {"reach-pillar", "square-nut", "round-nut"} <= set(task_names())
    assert make_task("square-nut") is make_task("square-nut")  # host set-up happens once
    assert make_task("square-nut", horizon=7).config.horizon == 7
    with pytest.raises(ElicitError, match="unknown task 'nope'"):
        make_task("nope")
    with pytest.raises(ElicitError, match="no setting"):
        make_task("square-nut", bogus=1)


def test_ctrl_from_action_by_hand():
    task = make_task("square-nut")
    qpos = np.array([0.1, -0.2, 0.05, 0.3, 0.01, 0.01])
    action = np.array([1.0, -0.5, 2.0, 0.7, -0.7, -1.0, 1.0])
    ctrl = task.ctrl_from_action(qpos, action)
    # pos: q + a * 0.02 (a clipped to 1): 0.1+0.02, -0.2-0.01, 0.05+0.02; yaw: 0.3 - 1*0.15;
    # gripper +1 (closed): fingers target (1 - 1) * 0.02 = 0; roll/pitch (0.7, -0.7) ignored.
    np.testing.assert_allclose(ctrl, [0.12, -0.21, 0.07, 0.15, 0.0, 0.0], atol=1e-7)
    opened = task.ctrl_from_action(qpos, np.array([0, 0, 0, 0, 0, 0, -1.0]))
    np.testing.assert_allclose(opened[4:], [0.04, 0.04])  # (1 + 1) * 0.02


def test_yaw_roundtrip():
    yaws = np.array([-3.0, -1.0, 0.0, 0.5, 2.9])
    np.testing.assert_allclose(quat_yaw(yaw_quat(yaws)), yaws, atol=1e-12)


def test_success_by_hand():
    task = make_task("square-nut")
    obs = np.zeros((4, OBS_DIM))
    obs[:, 7:9] = 0.04  # open fingers
    obs[:, 9:12] = [0.1 + 0.02, 0.1, 0.007]  # 2 cm off the peg axis (tol 3 cm), resting low
    obs[1, 9] = 0.1 + 0.04  # 4 cm off: not centred
    obs[2, 11] = 0.1  # on top of the peg: not low
    obs[3, 7] = 0.005  # a closed finger: not released
    assert task.success_from_obs(obs).tolist() == [True, False, False, False]


def test_initial_states_seeded_and_randomised():
    task = make_task("square-nut")
    q1, _ = task.init_states(np.arange(5))
    q2, _ = task.init_states(np.arange(5))
    np.testing.assert_array_equal(q1, q2)
    assert len({round(float(x), 6) for x in q1[:, 6]}) == 5  # nut x differs by seed
    cfg = task.config
    assert np.all((q1[:, 6] >= cfg.nut_x[0]) & (q1[:, 6] <= cfg.nut_x[1]))
    yaw = quat_yaw(q1[:, 9:13])
    assert np.all((yaw >= cfg.nut_yaw[0] - 1e-6) & (yaw <= cfg.nut_yaw[1] + 1e-6))


def test_c_backend_deterministic_across_thread_counts_and_masked():
    task = make_task("reach-pillar")
    actions = np.array(
        [
            [0.5, 0.2, 0.0, 0, 0, 0.3, -1.0],
            [0.6, -0.4, 0.2, 0, 0, -0.5, 1.0],
            [0.5, 0.2, 0.0, 0, 0, 0.3, -1.0],
        ]
    )
    outs = []
    for threads in (2, 1, 3):  # one chunk per thread, the calling thread steps the last
        with BatchSim(task, 3, threads=threads) as sim:
            sim.reset_seeds(np.array([4, 5, 6]))
            for _ in range(5):
                obs = sim.step(actions, active=np.array([True, True, False]))
            outs.append(obs)
    np.testing.assert_array_equal(outs[0], outs[1])
    np.testing.assert_array_equal(outs[0], outs[2])
    with BatchSim(task, 1) as sim:
        start = sim.reset_seeds(np.array([6]))
    np.testing.assert_array_equal(outs[0][2], start[0])  # the inactive env never moved
    assert outs[0][0, 0] > start[0, 0]  # +x action moved the others


def test_mjx_matches_c_mujoco_on_square_nut_grasp():
    """The base operator's actions replayed open-loop: approach, grasp and lift agree; the
    jitted MJX replay is pure (same inputs, same outputs)."""
    from elicit_jax.sim.collect import operator_rng
    from elicit_jax.sim.operators import make_operator
    from elicit_jax.sim.rollout_mjx import trajectory_fn

    task = make_task("square-nut")
    op = make_operator(task, "base")
    seeds = np.array([0, 1])
    steps = 40
    with BatchSim(task, 2, threads=1) as sim:
        obs = sim.reset_seeds(seeds)
        op.reset(obs, operator_rng(0, "base"))
        c, acts = [obs.copy()], []
        for _ in range(steps):
            a = op.act(obs)
            acts.append(a)
            obs = sim.step(a)
            c.append(obs.copy())
    c, acts = np.stack(c, 1), np.stack(acts, 1)
    assert (op.phase >= 3).all()  # the replay covers the grasp and the start of the lift
    q, m = task.init_states(seeds)
    fn = trajectory_fn(task)
    mjx = np.asarray(fn(q.astype(np.float32), m.astype(np.float32), acts.astype(np.float32)))
    np.testing.assert_allclose(mjx[..., 0:3], c[..., 0:3], atol=2e-3)  # eef position
    np.testing.assert_allclose(mjx[..., 9:12], c[..., 9:12], atol=2e-3)  # nut position
    np.testing.assert_allclose(mjx, c, atol=1e-2)
    again = fn(q.astype(np.float32), m.astype(np.float32), acts.astype(np.float32))
    np.testing.assert_array_equal(np.asarray(again), mjx)


@pytest.mark.parametrize("at_step", [0, 3])
def test_c_backend_flags_and_freezes_a_diverged_env(at_step):
    """A non-finite velocity makes MuJoCo reset the data; the env is flagged and frozen, both
    on the first control step (the clock alone cannot show that reset) and later."""
    task = make_task("reach-pillar")
    actions = np.tile([0.3, 0.0, 0.0, 0, 0, 0, -1.0], (3, 1))
    with BatchSim(task, 3, threads=2) as sim:
        sim.reset_seeds(np.array([1, 2, 3]))
        for t in range(6):
            if t == at_step:
                sim.datas[1].qvel[0] = np.nan
            sim.step(actions)
            if t == at_step:
                frozen = sim.qpos()[1]
        assert sim.unstable.tolist() == [False, True, False]
        assert not sim.success[1]
        np.testing.assert_array_equal(sim.qpos()[1], frozen)


def test_c_backend_sends_mujoco_warnings_to_the_log_not_the_terminal(capfd, caplog):
    """A diverging env makes C MuJoCo warn; while a BatchSim is open the message goes to the
    ``elicit_jax.sim.mujoco`` logger (and is counted), not to stdout/stderr or
    MUJOCO_LOG.TXT; closing the sim restores MuJoCo's own handler."""
    import logging

    import mujoco

    from elicit_jax.sim.rollout_mujoco import warning_count

    task = make_task("reach-pillar")
    before = warning_count()
    with caplog.at_level(logging.INFO, logger="elicit_jax.sim.mujoco"):
        with BatchSim(task, 2, threads=1) as sim, BatchSim(task, 1, threads=1):
            sim.reset_seeds(np.array([1, 2]))
            sim.datas[0].qvel[0] = np.nan
            sim.step(np.zeros((2, 7)))
            assert sim.unstable.tolist() == [True, False]
        assert mujoco.get_mju_user_warning() is None
    out, err = capfd.readouterr()
    assert "unstable" not in out + err
    assert warning_count() == before + 1
    assert [r.getMessage() for r in caplog.records] == [
        "MuJoCo warning: Nan, Inf or huge value in QVEL at DOF 0. The simulation is unstable. "
        "Time = 0.0000."
    ]
