"""The robosuite backend end to end: the MuJoCo-3.17 adaptations, a scripted base operator
that succeeds in NutAssemblySquare, paired initial states across policies and workers,
``evaluate --env-from`` on a file written by ``export``, and the one-line error of a file
whose observation keys do not match the environment.

robosuite environments take seconds to build: every run here uses two workers, so the whole
module shares one pool (``shared_pool``: the CLI runs in this process reuse it too). In CI
(ELICIT_JAX_REQUIRE_ROBOSUITE=1) these tests must run: a missing robosuite is a failure there,
a skip elsewhere.
"""

import h5py
import numpy as np
import pytest
from fixtures_data import skip_without_robosuite
from typer.testing import CliRunner

from elicit_jax.artifact import read_header
from elicit_jax.cli import app
from elicit_jax.errors import ElicitError

skip_without_robosuite()


def _run(args):
    return CliRunner().invoke(app, args)


def _ok(args):
    result = _run(args)
    assert result.exit_code == 0, (result.output, result.exception)
    return result


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """One base demo collected with the CLI, a tiny policy trained on it, its robomimic export."""
    from elicit_jax.data.demos import read_demos
    from elicit_jax.policy.train import train_policy
    from tests.fixtures_data import tiny_train_config

    d = tmp_path_factory.mktemp("robosuite")
    out = _ok(["collect", "--task", "robosuite-square", "--operator", "base", "--episodes", "2",
               "--seed", "0", "--max-attempts", "4", "--threads", "2",
               "-o", str(d / "base.parquet")])  # fmt: skip
    demos = read_demos(d / "base.parquet")
    train_policy(demos, tiny_train_config(), d / "run", quiet=True)
    _ok(["export", str(d / "base.parquet"), "--format", "robomimic", "-o", str(d / "base.hdf5")])
    return {"dir": d, "demos": demos, "collect_output": out.output}


@pytest.fixture(scope="module")
def pool():
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.rollout_robosuite import close_shared, shared_pool

    yield shared_pool(make_task("robosuite-square").spec, 2)
    close_shared()


def test_compat_layer_is_needed_idempotent_and_fixes_the_calls():
    import mujoco
    from robosuite.utils import binding_utils

    from elicit_jax.sim import robosuite_compat as rc

    assert rc.joint_enum_broken() and rc.fullm_changed()  # MuJoCo 3.17, as measured
    assert rc.ensure_compat() == ["joint-type", "mj_fullM"]
    assert rc.ensure_compat() == ["joint-type", "mj_fullM"]  # applied once
    assert binding_utils.MjModel.get_joint_qpos_addr is rc.get_joint_qpos_addr
    xml = """<mujoco><worldbody><body><freejoint name="f"/><geom size=".1"/>
      <body><joint name="h" type="hinge"/><joint name="b" type="ball"/><geom size=".1"/>
      </body></body></worldbody></mujoco>"""
    m = binding_utils.MjModel(mujoco.MjModel.from_xml_string(xml))
    assert m.get_joint_qpos_addr("f") == (0, 7)
    assert m.get_joint_qpos_addr("h") == 7
    assert m.get_joint_qpos_addr("b") == (8, 12)
    assert m.get_joint_qvel_addr("b") == (7, 10)
    d = binding_utils.MjData(m)
    mujoco.mj_forward(m._model, d._data)
    dense = np.zeros((m.nv, m.nv))
    from robosuite.controllers.parts import controller

    controller.mujoco.mj_fullM(m._model, dense, d.qM)  # robosuite's call, adapted
    expected = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m._model, d._data, expected)
    assert np.allclose(dense, expected) and dense[0, 0] > 0


def test_scripted_base_operator_succeeds(work):
    demos = work["demos"]
    assert demos.n_episodes == 2 and demos.obs_dim == 23 and demos.action_dim == 7
    assert "attempt success 2/2" in " ".join(work["collect_output"].split())
    assert np.isfinite(demos.obs).all() and demos.success.all()
    for e in range(2):  # the last state before success: the nut over its peg, below its top
        nut = demos.obs[demos.episode == e][-1, 16:19]
        assert np.linalg.norm(nut[:2] - np.array([0.23, 0.1])) < 0.03 and nut[2] < 0.95
    assert demos.provenance["env_args"]["env_name"] == "NutAssemblySquare"


def test_paired_initial_states_identical_across_policies_and_workers(work, pool):
    from elicit_jax.policy.base import jitted_act
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.sim.rollout_robosuite import rollout_policy

    policy = load_policy(next((work["dir"] / "run").glob("seed*")), "final").policy
    spec = pool.spec
    seeds = np.array([11, 12, 13])
    a = rollout_policy(spec, jitted_act(), policy, seeds, 3, 2, pool)
    b = rollout_policy(spec, jitted_act(), policy, seeds[::-1], 3, 2, pool)  # other workers
    assert np.array_equal(a["init_obs"], b["init_obs"][::-1])
    assert not np.allclose(a["init_obs"][0, 16:19], a["init_obs"][1, 16:19])  # seeds differ
    assert a["env_steps"] == 9 and not a["success"].any()


def test_recorded_states_and_seeded_noise_do_not_depend_on_the_worker(work, pool):
    """What CUPID and Demo-SCORE read on robosuite: every state the policy acted in and the
    action taken, the exploration noise drawn per rollout seed (the same whichever worker)."""
    from elicit_jax.policy.base import jitted_act
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.sim.rollout_robosuite import rollout_policy

    policy = load_policy(next((work["dir"] / "run").glob("seed*")), "final").policy
    seeds = np.array([21, 22, 23])
    a = rollout_policy(pool.spec, jitted_act(), policy, seeds, 3, 2, pool, True, 0.2)
    b = rollout_policy(pool.spec, jitted_act(), policy, seeds[::-1], 3, 2, pool, True, 0.2)
    clean = rollout_policy(pool.spec, jitted_act(), policy, seeds, 3, 2, pool, True)
    assert a["states"].shape == (3, 3, 23) and a["actions"].shape == (3, 3, 7)
    assert a["state_mask"].all()  # no success in 3 steps: every step recorded
    assert np.allclose(a["states"][:, 0], a["init_obs"])  # the first state is the reset's
    for key in ("states", "actions"):
        assert np.allclose(a[key], b[key][::-1], atol=1e-5)
    # at the first step the states agree, so the actions differ by exactly the seeded noise
    noise = np.stack([np.random.default_rng(s).normal(size=7) for s in seeds]) * 0.2
    assert np.allclose(a["actions"][:, 0] - clean["actions"][:, 0], noise, atol=1e-5)


def test_evaluate_task_and_env_from_exported_file(work):
    d = work["dir"]
    _ok(["evaluate", "--policy", f"A={d / 'run'}", "--policy", f"B={d / 'run'}",
         "--task", "robosuite-square", "--rollouts", "2", "--horizon", "4",
         "--checkpoint", "final", "--workers", "2", "-o", str(d / "task.parquet")])  # fmt: skip
    import pandas as pd

    rows = pd.read_parquet(d / "task.parquet")
    a, b = rows[rows.policy == "A"], rows[rows.policy == "B"]
    assert list(a.init_seed) == list(b.init_seed) and len(a) == 2
    assert read_header(d / "task.parquet")["backend"] == "robosuite"
    res = _ok(["evaluate", "--policy", str(d / "run"), "--env-from", str(d / "base.hdf5"),
               "--rollouts", "1", "--horizon", "3", "--checkpoint", "final", "--workers", "2",
               "-o", str(d / "env_from.parquet")])  # fmt: skip
    assert "robosuite" in res.output
    header = read_header(d / "env_from.parquet")
    assert header["config"]["env_from"] == str(d / "base.hdf5") and "env_from" in header["inputs"]


def test_env_from_mismatched_file_one_line_error(work):
    import shutil

    d = work["dir"]
    bad = d / "bad.hdf5"
    shutil.copy(d / "base.hdf5", bad)
    with h5py.File(bad, "a") as f:
        obs = f["data/demo_0/obs"]
        t = obs["object"].shape[0]
        del obs["object"]
        obs.create_dataset("object", data=np.zeros((t, 10)))
    res = _run(["evaluate", "--policy", str(d / "run"), "--env-from", str(bad),
                "--rollouts", "1", "--checkpoint", "final", "--workers", "2",
                "-o", str(d / "bad.parquet")])  # fmt: skip
    assert res.exit_code != 0 and isinstance(res.exception, ElicitError), res.output
    line = str(res.exception)  # what `elicit-jax` prints after "error: "
    assert "\n" not in line and line.startswith(f"{bad}: observation keys differ")
    assert "object (file 10, NutAssemblySquare 14)" in line
    assert not (d / "bad.parquet").exists()


def test_key_differences_and_wrong_backend():
    from elicit_jax.sim.evaluate import resolve_backend
    from elicit_jax.sim.evaluate_robosuite import check_obs, key_differences

    diff = key_differences(["a", "b", "c"], {"a": 3, "b": 4}, {"a": 3, "b": 5, "c": 1}, "E")
    assert diff == ["b (file 4, E 5)", "c (file missing, E 1)"]
    with pytest.raises(ElicitError, match="reads 9 values"):
        check_obs("f.hdf5", ["a", "b"], 9, {"a": 3, "b": 4}, {"a": 3, "b": 4}, "E")
    with pytest.raises(ElicitError, match="--backend robosuite"):
        resolve_backend("mujoco", "robosuite-square")
    assert resolve_backend("auto", "robosuite-round") == "robosuite"


def test_elicit_session_on_robosuite_square_end_to_end(work):
    """collect → train → score → fit-thresholds → elicit with the scripted base operator:
    practice, prompt, a demonstration scored live, written like a MuJoCo task's session and
    replayed exactly; the scene the browser gets is drawn from primitives only."""
    from elicit_jax.elicit.replay import replay_episode
    from elicit_jax.elicit.store import SessionStore
    from elicit_jax.sim.env import make_task
    from elicit_jax.web.scene import body_poses, scene_description

    d = work["dir"]
    _ok(["score", "--policy", str(d / "run"), "--demos", str(d / "base.parquet"),
         "--lambda", "0.4", "--eta", "0.05", "-o", str(d / "scores.parquet")])  # fmt: skip
    _ok(["fit-thresholds", "--scores", str(d / "scores.parquet"), "--lambda", "0.4",
         "--eta", "0.05", "-o", str(d / "thresholds.json")])  # fmt: skip
    res = _ok(["elicit", "--task", "robosuite-square", "--policy", str(d / "run"),
               "--base-demos", str(d / "base.parquet"), "--thresholds", str(d / "thresholds.json"),
               "--operator", "scripted:base", "--practice", "1", "--prompt", "1", "--demos", "1",
               "--max-episodes", "3", "-o", str(d / "session")])  # fmt: skip
    out = " ".join(res.output.split())
    assert "e0000 practice PRACTICE" in out and "e0001 demonstration ACCEPTED" in out
    store = SessionStore(d / "session")
    assert store.header()["task"] == "robosuite-square"
    practice, demo = store.read_episode(0), store.read_episode(1)
    assert practice.verdict == "practice" and demo.verdict == "accepted" and demo.success
    assert demo.n_scored == demo.length and np.isfinite(demo.compatibility).all()
    assert demo.qpos.shape == (demo.length, 23) and demo.obs.shape == (demo.length, 23)
    assert read_header(store.demos_path)["n_episodes"] == 1
    task = make_task("robosuite-square")
    replay = replay_episode(task, demo)  # the same robosuite environment, reused
    assert np.array_equal(replay["qpos"], demo.qpos) and bool(replay["success"])

    scene = scene_description(task.mj_model, task.name)
    types = {it["type"] for it in scene["items"]}
    assert types <= {"plane", "box", "cylinder", "sphere", "capsule"} and "box" in types
    assert all(it["kind"] == "geom" for it in scene["items"])  # robosuite's sites stay hidden
    named = {scene["bodies"][it["body"]] for it in scene["items"]}
    assert {"table", "peg1", "SquareNut_main", "robot0_link4", "gripper0_right_leftfinger"} <= named
    assert scene["gripper"] == "gripper0_right_eef" and scene["origin"] == (0.0, 0.0, 0.82)
    import mujoco

    data = mujoco.MjData(task.mj_model)
    data.qpos[:] = demo.qpos[0]
    mujoco.mj_kinematics(task.mj_model, data)
    poses = body_poses(data, scene["origin"])
    table = scene["bodies"].index("table")
    assert abs(poses[table, 2] + 0.025) < 1e-6  # table top (0.82 up) drawn at height 0


def test_session_environment_matches_workers_and_leaves_numpy_alone(pool):
    """The session's in-process environment starts from the same initial state as a worker
    given the same seed, puts NumPy's global generator back, and is reused once closed."""
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.rollout_robosuite import PoolBatch
    from elicit_jax.sim.single import control_period, open_env

    task = make_task("robosuite-square")
    np.random.seed(123)
    expected = np.random.random(3)
    np.random.seed(123)
    with open_env(task) as env:
        mine = env.reset_seeds(np.array([11]))[0].copy()
    assert np.array_equal(np.random.random(3), expected)
    with open_env(task) as again:
        assert again is env  # given back, taken again: built once per process
    workers = PoolBatch(pool).reset_seeds(np.array([11, 12]))
    assert np.allclose(mine, workers[0], atol=1e-6) and not np.allclose(mine, workers[1])
    assert control_period(task) == 0.05


def test_conflict_down_demos_conflict_by_their_own_states(work, tmp_path):
    """The conflicting operator's demos are measured to conflict, each one (column
    ``conflicts``), and the base demos measured not to; ``--require`` keeps only verified
    demos and says how many it left out."""
    from elicit_jax.data.demos import read_demos

    base = work["demos"]
    assert not base.extra["conflicts"].any() and not base.extra["down_first"].any()
    out = _ok(["collect", "--task", "robosuite-square", "--operator", "conflict-down",
               "--episodes", "2", "--seed", "3", "--threads", "2", "--require", "conflicts",
               "-o", str(tmp_path / "down.parquet")])  # fmt: skip
    assert "2 of 2 conflict" in " ".join(out.output.split())
    down = read_demos(tmp_path / "down.parquet")
    assert down.extra["conflicts"].all() and down.extra["down_first"].all()
    refused = _run(["collect", "--task", "robosuite-square", "--operator", "base",
                    "--episodes", "2", "--seed", "0", "--max-attempts", "2", "--threads", "2",
                    "--require", "conflicts", "-o", str(tmp_path / "no.parquet")])  # fmt: skip
    assert refused.exit_code != 0 and "2 of them not 'conflicts'" in str(refused.exception)
    assert not (tmp_path / "no.parquet").exists()


def test_remembered_action_dims_step_exactly_as_robosuite():
    """The evaluation speed-up (``make_env(fast=True)``: each robot remembers its action size)
    changes no number: from the same seeded initial states and actions, across a reset (which
    builds new controllers), both environments give the same observations and successes to
    the bit, and the remembered size is recomputed for a new controller."""
    from elicit_jax.sim import robosuite_env as rs
    from elicit_jax.sim.env import make_task

    spec = make_task("robosuite-round").spec
    plain, fast = rs.make_env(spec, 1000, fast=False), rs.make_env(spec, 1000)
    assert not getattr(type(plain.robots[0]), "_elicit_remembers", False)
    assert type(fast.robots[0])._elicit_remembers and fast.robots[0].action_dim == 7
    actions = np.random.default_rng(0).uniform(-0.6, 0.6, (2, 12, 7))
    for seed, steps in zip((5, 6), actions, strict=True):
        runs = []
        for env in (plain, fast):
            obs = [rs.flat_obs(rs.reset_seeded(env, seed), spec.obs_keys)]
            for a in steps:
                d, *_ = env.step(a)
                obs.append(np.append(rs.flat_obs(d, spec.obs_keys), rs.success(env)))
            runs.append(np.concatenate(obs[1:]))
        assert np.array_equal(runs[0], runs[1])
        robot = fast.robots[0]
        assert robot.__dict__["_elicit_action_dim"][0] is robot.composite_controller
    plain.close()
    fast.close()


def test_evaluation_loop_gives_the_same_rollouts_with_and_without_the_speed_up(work, pool):
    """Through the evaluation's own loop (worker processes, refilled slots): a pool built as
    robosuite builds its environments (``fast=False``) and the shared, sped-up pool record
    the same states, actions, successes and lengths."""
    from elicit_jax.policy.base import jitted_act
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.sim.rollout_robosuite import SHARED_HORIZON, EnvPool, rollout_policy

    policy = load_policy(next((work["dir"] / "run").glob("seed*")), "final").policy
    seeds = np.array([31, 32, 33])
    with EnvPool(pool.spec, 2, SHARED_HORIZON, fast=False) as plain:
        old = rollout_policy(pool.spec, jitted_act(), policy, seeds, 6, 2, plain, True)
    new = rollout_policy(pool.spec, jitted_act(), policy, seeds, 6, 2, pool, True)
    for key in ("success", "steps_to_success", "ret", "unstable", "init_obs", "states",
                "state_mask", "actions", "env_steps"):  # fmt: skip
        assert np.array_equal(old[key], new[key]), key
