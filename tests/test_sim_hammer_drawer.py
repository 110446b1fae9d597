"""The ``hammer-drawer`` task: layout, success, initial states, operators, MJX vs C MuJoCo."""

import numpy as np
import pytest

from elicit_jax.sim.collect import operator_rng, run_batch
from elicit_jax.sim.env import OBS_DIM, make_task, quat_yaw, task_names
from elicit_jax.sim.operators import make_operator, operator_names
from elicit_jax.sim.rollout_mujoco import BatchSim
from elicit_jax.sim.tasks.hammer_drawer import BAR_X, BAR_Z, FLOOR_Z, HAMMER_Z, INTERIOR_X

SEEDS = np.arange(200, 210)


@pytest.fixture(scope="module")
def task():
    return make_task("hammer-drawer")


@pytest.fixture(scope="module")
def runs(task):
    out = {}
    for name in operator_names("hammer-drawer"):
        op = make_operator(task, name)
        with BatchSim(task, len(SEEDS)) as sim:
            out[name] = run_batch(task, op, sim, SEEDS, operator_rng(0, name))
    return out


def test_registry_and_model(task):
    assert "hammer-drawer" in task_names()
    assert task.config.horizon == 175
    names = set(operator_names("hammer-drawer"))
    assert {"base", "same-style", "mild", "conflict-flip", "conflict-order"} <= names
    m = task.mj_model
    assert m.nsensordata == OBS_DIM  # the sensors are the 23-D observation
    assert m.npair == 12  # contacts stay few and explicit
    assert m.nq == 6 + 7 + 1  # gripper, hammer free joint, drawer slide


def test_success_by_hand(task):
    obs = np.zeros((6, OBS_DIM))
    obs[:, 9:12] = [INTERIOR_X, 0.0, FLOOR_Z + HAMMER_Z]  # hammer lying in the closed drawer
    obs[1, 22] = 0.02  # drawer 2 cm open (tolerance 1 cm): not closed
    obs[2, 9] = INTERIOR_X + 0.07  # beyond the interior's half length 0.065
    obs[3, 11] = HAMMER_Z  # on the floor (below the drawer's floor at 0.03)
    obs[4, [9, 22]] = [INTERIOR_X - 0.15, 0.15]  # inside the drawer, but the drawer is open
    # 5 mm open (closed within 1 cm): interior centre at 0.2 - 0.005 = 0.195; y 0.09 < 0.1
    obs[5, [9, 10, 22]] = [0.195, 0.09, 0.005]
    assert task.success_from_obs(obs).tolist() == [True, False, False, False, False, True]


def test_initial_states_seeded_and_randomised(task):
    q1, m1 = task.init_states(np.arange(6))
    q2, _ = task.init_states(np.arange(6))
    np.testing.assert_array_equal(q1, q2)
    assert m1.shape == (6, 0, 3)
    cfg = task.config
    assert len({round(float(x), 6) for x in q1[:, 6]}) == 6  # hammer x differs by seed
    assert np.all((q1[:, 7] >= cfg.hammer_y[0]) & (q1[:, 7] <= cfg.hammer_y[1]))
    yaw = quat_yaw(q1[:, 9:13])
    assert np.all((yaw >= cfg.hammer_yaw[0] - 1e-6) & (yaw <= cfg.hammer_yaw[1] + 1e-6))
    assert np.all(q1[:, 13] == 0.0)  # the drawer starts closed
    with BatchSim(task, 6, threads=1) as sim:
        obs = sim.reset_seeds(np.arange(6))
    assert not sim.success.any()
    np.testing.assert_allclose(obs[:, 9:12], q1[:, 6:9], atol=1e-6)  # hammer position
    np.testing.assert_allclose(obs[:, 16:19], q1[:, 6:9] - obs[:, 0:3], atol=1e-6)  # yaw 0
    # drawer handle in the (unrotated) eef frame: bar axis (0.077, 0, 0.055) minus the eef
    bar = np.array([BAR_X, 0.0, BAR_Z])
    np.testing.assert_allclose(obs[:, 19:22], bar - obs[:, 0:3], atol=1e-6)
    np.testing.assert_allclose(BAR_X, 0.077, atol=1e-9)  # 0.2 - 0.065 - 0.01 - 0.048
    assert np.all(obs[:, 22] == 0.0)


def test_operators_solve_the_task(runs, task):
    assert runs["base"]["success"].all()
    for name, out in runs.items():
        assert out["success"].mean() >= 0.9, (name, out["success"].mean())
        assert np.abs(out["action"]).max() <= 1.0
    lengths = runs["base"]["length"]
    assert lengths.max() < task.config.horizon
    # the last observation recorded is one control step before the success
    final = np.stack([o[n - 1] for o, n in zip(runs["base"]["obs"], lengths, strict=True)])
    assert np.all(final[:, 22] < 0.03)  # the drawer was opened, then pushed (almost) shut
    opened = [o[:n, 22].max() for o, n in zip(runs["base"]["obs"], lengths, strict=True)]
    assert min(opened) > 0.14


def _grasp_yaw(out):
    """Wrist yaw minus hammer yaw where the gripper first closes on the hammer."""
    rows = []
    for obs, act in zip(out["obs"], out["action"], strict=True):
        t_open = int(np.argmax(act[:, 6] < 0))  # the jaw opens for the hammer after the hook
        t = t_open + int(np.argmax(act[t_open:, 6] > 0))
        rows.append(quat_yaw(obs[t, 3:7]) - quat_yaw(obs[t, 12:16]))
    return np.abs(np.angle(np.exp(1j * np.asarray(rows))))


def test_styles_differ_as_designed(runs):
    assert np.all(_grasp_yaw(runs["base"]) < 0.15)
    assert np.all(_grasp_yaw(runs["same-style"]) < 0.15)
    assert np.all(_grasp_yaw(runs["conflict-flip"]) > np.pi - 0.25)  # half a turn
    assert np.all(_grasp_yaw(runs["conflict-flip-pause"]) > np.pi - 0.25)

    def placed_yaw(out):
        return np.array(
            [quat_yaw(o[n - 1, 12:16]) for o, n in zip(out["obs"], out["length"], strict=True)]
        )

    assert np.all(np.abs(placed_yaw(runs["base"]) - np.pi / 2) < 0.3)  # head towards +y
    assert np.all(np.abs(placed_yaw(runs["conflict-mirror"]) + np.pi / 2) < 0.3)  # -y

    def travel_before_rising(out):
        """Hammer's xy travel from its pick-up until it first rises above 9 cm."""
        rows = []
        for obs in out["obs"]:
            t0 = int(np.argmax(obs[:, 11] > HAMMER_Z + 0.01))
            t1 = int(np.argmax(obs[:, 11] > 0.09))
            rows.append(np.linalg.norm(obs[t1, 9:11] - obs[t0, 9:11]))
        return np.array(rows)

    assert np.all(travel_before_rising(runs["base"]) < 0.03)  # base: straight up first
    assert np.all(travel_before_rising(runs["conflict-order"]) > 0.1)  # across first, low


def test_mjx_matches_c_mujoco_on_opening_and_grasp(runs, task):
    """The base operator's first 70 actions replayed open-loop on MJX (hook the handle, pull
    the drawer open, reach down to the hammer) agree with C MuJoCo."""
    from elicit_jax.sim.rollout_mjx import trajectory_fn

    steps = 70
    c = runs["base"]["obs"][:2, : steps + 1]
    acts = runs["base"]["action"][:2, :steps]
    assert c[:, -1, 22].min() > 0.14  # the replay covers the pull
    q, m = task.init_states(SEEDS[:2])
    mjx = np.asarray(trajectory_fn(task)(q.astype(np.float32), m.astype(np.float32), acts))
    np.testing.assert_allclose(mjx[..., 0:3], c[..., 0:3], atol=3e-3)  # eef position
    np.testing.assert_allclose(mjx[..., 22], c[..., 22], atol=3e-3)  # drawer opening
    np.testing.assert_allclose(mjx[..., 9:12], c[..., 9:12], atol=3e-3)  # hammer position
    np.testing.assert_allclose(mjx, c, atol=2e-2)


def test_flip_pause_holds_still_where_the_base_moves_on(runs):
    """Both open the drawer the same way; once the gripper has risen off the bar (the first
    step with the jaw open for the hammer), the base moves on at once while
    'conflict-flip-pause' holds still for its pause, with the drawer open the same amount."""
    from elicit_jax.sim.operators.hammer_drawer import STYLES

    n = dict(STYLES["conflict-flip-pause"][0].choices)["pause_steps"]

    def first_open(out):
        return [int(np.argmax(a[:, 6] < 0)) for a in out["action"]]

    for i, t in enumerate(first_open(runs["base"])):
        assert np.abs(runs["base"]["action"][i, t, 0:3]).max() > 0.5
    for i, t in enumerate(first_open(runs["conflict-flip-pause"])):
        acts, obs = runs["conflict-flip-pause"]["action"][i], runs["conflict-flip-pause"]["obs"][i]
        assert np.abs(acts[t : t + n, 0:6]).max() == 0.0
        assert np.abs(acts[t + n, 0:6]).max() > 0.5
        assert obs[t, 22] > 0.14  # the drawer is open: a state the base passes through
