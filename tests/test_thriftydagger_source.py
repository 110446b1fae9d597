"""benchmarks/thriftydagger_source.py: ThriftyDAgger's demo pickle read, split and written.

The real ``robosuite-30.pkl`` is not in the repository (its repository states no licence) and
is never downloaded, so a tiny file in its format (a pickle of ``{"obs": (N, 51), "act":
(N, 7)}`` float64 arrays, episodes stacked) stands in: it goes through the converter to a
robomimic file and into this project's demos, with hand-set values checked on the way; a
malformed or foreign file stops with one line naming it. One test rebuilds a recorded step
in robosuite 1.5 (skipped without robosuite).
"""

import hashlib
import importlib.util
import os
import pickle
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="module")
def ts():
    sys.path.insert(0, str(BENCH))
    spec = importlib.util.spec_from_file_location(
        "thriftydagger_source", BENCH / "thriftydagger_source.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    yield module
    sys.path.remove(str(BENCH))


ANGLES = np.array([0.1, -1.2, 2.0, -2.5, -1.5, 3.0])
"""Hand-set UR5e joint angles of every synthetic step (3.0 rad: cos < 0, sin > 0)."""


def _row(ts, nut_xy: tuple[float, float], t: int) -> np.ndarray:
    o = np.zeros(51)

    def put(name, v):
        a, b = ts.LAYOUT[name]
        o[a:b] = v

    put("nut_pos", [nut_xy[0], nut_xy[1], 0.83])
    put("nut_quat", [0.0, 0.0, 0.6, 0.8])  # x, y, z, w
    put("joint_cos", np.cos(ANGLES + 0.01 * t))
    put("joint_sin", np.sin(ANGLES + 0.01 * t))
    put("eef_pos", [-0.2 + 0.01 * t, 0.0, 0.98])
    put("eef_quat", [-0.68, 0.73, 0.01, -0.03])
    put("gripper_qpos", [-0.03, -0.28, -0.2, -0.03, -0.28, -0.2])
    return o


def _synthetic(ts, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Two episodes (3 and 2 steps); the nut jumps 0.35 m back to the table between them."""
    obs = np.stack([_row(ts, (-0.11, -0.2 + 0.001 * t), t) for t in range(3)]
                   + [_row(ts, (0.23, -0.1 - 0.35), t) for t in range(2)])  # fmt: skip
    act = np.zeros((5, 7))
    act[:, 0], act[:, -1] = [1, 1, 0, -1, 0], [-1, -1, 1, 1, -1]
    path.write_bytes(pickle.dumps({"obs": obs, "act": act}, protocol=4))
    return obs, act


def test_synthetic_file_round_trips_to_robomimic_and_demos(ts, tmp_path):
    src = tmp_path / "robosuite-30.pkl"
    obs, act = _synthetic(ts, src)
    got_obs, got_act = ts.read_source(src, sha256=hashlib.sha256(src.read_bytes()).hexdigest())
    np.testing.assert_array_equal(got_obs, obs)
    np.testing.assert_array_equal(got_act, act)
    spans = ts.split_episodes(got_obs, src, expected=2)
    assert spans == [(0, 3), (3, 5)]
    np.testing.assert_allclose(ts.arm_angles(got_obs[0]), ANGLES, atol=1e-12)
    np.testing.assert_allclose(ts.arm_angles(got_obs[4])[5], 3.01, atol=1e-12)
    np.testing.assert_array_equal(ts.xyzw_to_wxyz(ts.field(got_obs[0], "nut_quat")),
                                  [0.8, 0.0, 0.0, 0.6])  # fmt: skip

    # this project's 23-value layout, with hand-set gripper and object values
    view = {
        "robot0_eef_pos": ts.field(got_obs, "eef_pos"),
        "robot0_eef_quat": ts.field(got_obs, "eef_quat"),
        "robot0_gripper_qpos": np.tile([0.04, -0.04], (5, 1)),
        "object": np.concatenate([ts.field(got_obs, k) for k in
                                  ("nut_to_eef_pos", "nut_to_eef_quat", "nut_pos", "nut_quat")], 1),
    }  # fmt: skip
    eps = [{"actions": got_act[a:b], "obs": {k: v[a:b] for k, v in view.items()}}
           for a, b in spans]  # fmt: skip
    out = tmp_path / "human.hdf5"
    ts.write_robomimic(out, ts.TASK_ENV, eps, {"sha256": "x"})
    with h5py.File(out, "r") as f:
        assert sorted(f["data"]) == ["demo_0", "demo_1"]
        assert f["data/demo_1"].attrs["num_samples"] == 2
        np.testing.assert_array_equal(f["data/demo_0/rewards"][:], [0.0, 0.0, 1.0])
        assert '"robots": ["Panda"]' in f["data"].attrs["env_args"]

    from elicit_jax.data.robomimic import import_robomimic

    demos = import_robomimic(out, task="robosuite-round", operator="human")
    assert demos.obs.shape == (5, 23) and demos.action.shape == (5, 7)
    np.testing.assert_array_equal(demos.episode, [0, 0, 0, 1, 1])
    np.testing.assert_allclose(demos.obs[1, :3], [-0.19, 0.0, 0.98], atol=1e-6)
    np.testing.assert_allclose(demos.obs[3, 7:9], [0.04, -0.04], atol=1e-6)
    np.testing.assert_allclose(demos.obs[4, 19:23], [0.0, 0.0, 0.6, 0.8], atol=1e-6)
    np.testing.assert_array_equal(demos.action[:, 0], [1, 1, 0, -1, 0])
    assert demos.success.all()


def _one_line_error(excinfo, path: Path, text: str) -> None:
    msg = str(excinfo.value.code)
    assert "\n" not in msg and msg.startswith(f"error: {path}: ") and text in msg, msg


@pytest.mark.parametrize(
    ("payload", "text"),
    [
        (b"\x80\x04not a pickle", "not a ThriftyDAgger demo pickle"),
        (pickle.dumps([1, 2]), "expected a dict with 'obs' and 'act'"),
        (pickle.dumps({"obs": np.zeros((4, 50)), "act": np.zeros((4, 7))}), "(4, 50)"),
        (
            pickle.dumps({"obs": np.zeros((4, 51)), "act": np.zeros((3, 7))}),
            "4 observations but 3 actions",
        ),
        (pickle.dumps({"obs": np.full((2, 51), np.nan), "act": np.zeros((2, 7))}), "non-finite"),
    ],
)
def test_malformed_file_is_refused_in_one_line(ts, tmp_path, payload, text):
    path = tmp_path / "robosuite-30.pkl"
    path.write_bytes(payload)
    with pytest.raises(SystemExit) as e:
        ts.read_source(path, sha256=None)
    _one_line_error(e, path, text)


def test_a_pickle_that_would_run_code_is_refused_unrun(ts, tmp_path):
    marker = tmp_path / "ran"

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    path = tmp_path / "robosuite-30.pkl"
    path.write_bytes(pickle.dumps({"obs": Evil(), "act": None}))
    with pytest.raises(SystemExit) as e:
        ts.read_source(path, sha256=None)
    _one_line_error(e, path, "refuses to load")
    assert not marker.exists()


def test_other_bytes_and_episode_count_are_refused(ts, tmp_path):
    path = tmp_path / "robosuite-30.pkl"
    obs, _ = _synthetic(ts, path)
    with pytest.raises(SystemExit) as e:
        ts.read_source(path)  # the real file's hash
    _one_line_error(e, path, "SHA-256")
    with pytest.raises(SystemExit) as e:
        ts.split_episodes(obs, path, expected=30)
    _one_line_error(e, path, "found 2 episodes (nut jumps), expected 30")
    with pytest.raises(SystemExit) as e:
        ts.read_source(tmp_path / "missing.pkl")
    _one_line_error(e, tmp_path / "missing.pkl", "not found")


def test_reads_the_file_from_a_git_directory(ts, tmp_path):
    repo = tmp_path / "thriftydagger"
    repo.mkdir()
    _synthetic(ts, repo / ts.SOURCE_PATH)
    git = ["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", ts.SOURCE_PATH], check=True)
    subprocess.run([*git, "commit", "-q", "-m", "demo"], check=True)
    data = (repo / ts.SOURCE_PATH).read_bytes()
    (repo / ts.SOURCE_PATH).unlink()  # only the git objects hold it now
    assert ts.source_bytes(repo) == data
    assert ts.source_bytes(repo / ".git") == data
    with pytest.raises(SystemExit) as e:
        ts.source_bytes(tmp_path)
    _one_line_error(e, tmp_path, "neither robosuite-30.pkl nor a git directory")


def test_a_recorded_step_is_rebuilt_in_robosuite(ts, tmp_path):
    from fixtures_data import skip_without_robosuite

    skip_without_robosuite()
    import thriftydagger_rebuild as rb

    row = _row(ts, (-0.11, -0.2), 0)
    env = rb.make(ts.RECORDED)
    try:
        rb.set_recorded(env, row)
        o = env._get_observations(force_update=True)
        np.testing.assert_allclose(o["robot0_joint_pos"], ANGLES, atol=1e-9)
        np.testing.assert_allclose(o["RoundNut_pos"], [-0.11, -0.2, 0.83], atol=1e-9)
        np.testing.assert_allclose(o["RoundNut_quat"], [0.0, 0.0, 0.6, 0.8], atol=1e-9)
        np.testing.assert_allclose(o["robot0_gripper_qpos"], ts.field(row, "gripper_qpos"),
                                   atol=1e-9)  # fmt: skip
    finally:
        env.close()


def test_panda_finger_map_matches_the_panda_pads(ts):
    """The Panda view's finger map, checked against a Panda set by hand (robosuite 1.5)."""
    from fixtures_data import skip_without_robosuite

    skip_without_robosuite()
    import thriftydagger_rebuild as rb

    d0, slope, hi = rb.panda_fingers()
    assert hi == pytest.approx(0.04)
    env = rb.make(ts.TASK_ENV)
    try:
        sim, g = env.sim, env.robots[0].gripper["right"]
        adr = [sim.model.get_joint_qpos_addr(j) for j in g.joints]
        sim.data.qpos[adr] = [0.0208, -0.0208]
        sim.forward()
        assert rb.pad_distance(env) == pytest.approx(d0 + slope * 0.0208, abs=1e-6)
        assert rb.pad_distance(env) == pytest.approx(0.0486, abs=5e-4)  # probed by hand
    finally:
        env.close()
