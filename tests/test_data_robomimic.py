"""robomimic HDF5: import (obs keys, masks -> operators, filter keys), export as a new mask."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from fixtures_data import robomimic_demo, write_robomimic

from elicit_jax.artifact import file_sha256
from elicit_jax.data.demos import SOURCE_EPISODE, DemosWarning, read_demos
from elicit_jax.data.robomimic import import_robomimic
from elicit_jax.data.robomimic_export import add_mask
from elicit_jax.data.synthetic import ToyConfig, make_toy_robomimic
from elicit_jax.errors import ElicitError


@pytest.fixture
def mh_file(tmp_path):
    """Multi-human layout: demo_0..demo_11 (note demo_10 sorts after demo_9), operator masks."""
    rng = np.random.default_rng(0)
    lengths = {f"demo_{i}": 3 + i for i in range(12)}
    demos = {n: robomimic_demo(rng, t, success=n != "demo_4") for n, t in lengths.items()}
    masks = {
        "better_operator_1": ["demo_0", "demo_1", "demo_10", "demo_11"],
        "okay_operator_1": ["demo_2", "demo_3", "demo_4", "demo_5"],
        "worse_operator_2": ["demo_6", "demo_7", "demo_8", "demo_9"],
        "better": ["demo_0", "demo_1", "demo_10", "demo_11"],
        "train": [f"demo_{i}" for i in range(10)],
    }
    return write_robomimic(tmp_path / "low_dim.hdf5", demos, masks), demos


def test_import_default_low_dim_keys_in_numeric_demo_order(mh_file):
    path, raw = mh_file
    demos = import_robomimic(path)
    order = [f"demo_{i}" for i in range(12)]  # numeric, not lexicographic (demo_10 < demo_2)
    names = demos.extra[SOURCE_EPISODE]
    starts = [s for _, s, _ in demos.episode_bounds()]
    assert [names[s] for s in starts] == order
    assert [(f.name, f.start, f.stop) for f in demos.obs_fields] == [
        ("robot0_eef_pos", 0, 3),
        ("robot0_eef_quat", 3, 7),
        ("robot0_gripper_qpos", 7, 9),
        ("object", 9, 23),
    ]
    assert demos.obs_dim == 23 and demos.action_dim == 7 and demos.task == "NutAssemblySquare"
    s, e = demos.episode_bounds()[10][1:]  # demo_10
    np.testing.assert_allclose(demos.obs[s:e, 9:23], raw["demo_10"]["obs/object"], rtol=1e-6)
    np.testing.assert_allclose(demos.action[s:e], raw["demo_10"]["actions"], rtol=1e-6)
    outcome = {names[s]: bool(demos.success[s]) for s in starts}
    assert outcome["demo_4"] is False and sum(outcome.values()) == 11
    assert demos.provenance["sha256"] == file_sha256(path)
    assert demos.provenance["importer"] == "robomimic"


def test_progress_wraps_the_demos_read_and_is_told_the_file(mh_file):
    path, _ = mh_file
    calls = []

    def progress(items, what):
        calls.append((list(items), what))
        yield from items

    demos = import_robomimic(path, filter_key="better", progress=progress)
    assert calls == [(["demo_0", "demo_1", "demo_10", "demo_11"], "reading low_dim.hdf5")]
    assert demos.n_episodes == 4


def test_operators_from_mask_glob_and_filter_key(mh_file):
    path, _ = mh_file
    demos = import_robomimic(path, obs_keys=["object"], operators_from_masks="*_operator_*")
    by_name = dict(zip(demos.extra[SOURCE_EPISODE], demos.operator, strict=True))
    assert by_name["demo_10"] == "better_operator_1"
    assert by_name["demo_5"] == "okay_operator_1"
    assert by_name["demo_9"] == "worse_operator_2"
    # 12 demos, 4 of them in worse_operator_2: the other 8 get the default label
    with pytest.warns(DemosWarning, match=r"8 demos \(e\.g\. demo_0\) are listed by no mask"):
        part = import_robomimic(path, obs_keys=["object"], operators_from_masks="*_operator_2")
    assert dict(zip(part.extra[SOURCE_EPISODE], part.operator, strict=True))["demo_0"] == "unknown"
    sub = import_robomimic(path, obs_keys=["object"], filter_key="train", operator="me")
    assert sub.n_episodes == 10 and set(sub.operator) == {"me"}
    assert "demo_10" not in set(sub.extra[SOURCE_EPISODE])


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"obs_keys": ["robot0_joint_pos"]}, "data/demo_0/obs has no 'robot0_joint_pos'"),
        ({"obs_keys": ["agentview_image"]}, "image keys are not supported"),
        (
            {"filter_key": "valid"},
            "no mask/valid (available filter keys: better, better_operator_1",
        ),
        ({"operators_from_masks": "*_expert_*"}, "no mask key matches '*_expert_*'"),
        ({"operators_from_masks": "better*"}, "demo_0 is listed by both mask/better and"),
    ],
)
def test_import_errors_name_file_and_key(mh_file, kwargs, message):
    path, _ = mh_file
    with pytest.raises(ElicitError) as err:
        import_robomimic(path, **kwargs)
    assert str(err.value).startswith(f"{path}: ") and message in str(err.value)


def test_malformed_files(tmp_path):
    rng = np.random.default_rng(1)
    nan = robomimic_demo(rng, 4)
    nan["obs/object"][2, 5] = np.nan
    path = write_robomimic(tmp_path / "nan.hdf5", {"demo_0": robomimic_demo(rng, 3), "demo_1": nan})
    with pytest.raises(
        ElicitError, match=r"non-finite obs\[14\] value at episode 1 \(demo_1\), step 2"
    ):
        import_robomimic(path)
    short = robomimic_demo(rng, 4)
    short["obs/object"] = short["obs/object"][:3]
    path = write_robomimic(tmp_path / "short.hdf5", {"demo_0": short})
    with pytest.raises(ElicitError, match="data/demo_0/obs/object has 3 steps, actions 4"):
        import_robomimic(path)
    empty = {k: v[:0] for k, v in robomimic_demo(rng, 2).items()}
    path = write_robomimic(tmp_path / "empty.hdf5", {"demo_0": empty})
    with pytest.raises(ElicitError, match=r"data/demo_0 is empty \(0 steps\)"):
        import_robomimic(path)
    with h5py.File(tmp_path / "nodata.hdf5", "w") as f:
        f.create_group("mask")
    with pytest.raises(ElicitError, match="no 'data' group"):
        import_robomimic(tmp_path / "nodata.hdf5")
    (tmp_path / "text.hdf5").write_text("hello")
    with pytest.raises(ElicitError, match="not a readable HDF5 file"):
        import_robomimic(tmp_path / "text.hdf5")
    with pytest.raises(ElicitError, match="file not found"):
        import_robomimic(tmp_path / "absent.hdf5")


def test_export_mask_into_a_copy_robomimic_can_read(mh_file, tmp_path):
    path, _ = mh_file
    before = file_sha256(path)
    out = tmp_path / "copy.hdf5"
    chosen = add_mask(path, out, "compatible", ["demo_10", "demo_2", "demo_9"])
    assert chosen == ["demo_2", "demo_9", "demo_10"]
    assert file_sha256(path) == before  # the source is untouched
    with h5py.File(out, "r") as f:
        # how robomimic's FileUtils reads a filter key
        keys = [elem.decode("utf-8") for elem in np.array(f["mask/compatible"][:])]
        assert keys == chosen
        assert sorted(f["data"].keys()) == sorted(h5py.File(path, "r")["data"].keys())
        assert [x.decode() for x in f["mask/train"][:]] == [f"demo_{i}" for i in range(10)]
    again = import_robomimic(out, filter_key="compatible")
    assert list(dict.fromkeys(again.extra[SOURCE_EPISODE])) == chosen
    with pytest.raises(ElicitError, match="already has mask/train; pick another --mask-key"):
        add_mask(path, tmp_path / "c2.hdf5", "train", ["demo_1"])
    assert not (tmp_path / "c2.hdf5").exists()
    add_mask(path, tmp_path / "c2.hdf5", "train", ["demo_1"], overwrite=True)
    with h5py.File(tmp_path / "c2.hdf5", "r") as f:
        assert [x.decode() for x in f["mask/train"][:]] == ["demo_1"]
    with pytest.raises(ElicitError, match="has no demo 'demo_99'"):
        add_mask(path, tmp_path / "c3.hdf5", "k", ["demo_99"])
    with pytest.raises(ElicitError, match="output must differ"):
        add_mask(path, path, "k", ["demo_1"])
    with pytest.raises(ElicitError, match="empty mask"):
        add_mask(path, tmp_path / "c3.hdf5", "k", [])
    assert not (tmp_path / "c3.hdf5").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_synthetic_toy_is_deterministic_and_importable(tmp_path):
    cfg = ToyConfig(demos_per_operator=3, seed=7)
    counts = make_toy_robomimic(tmp_path / "a.hdf5", cfg)
    make_toy_robomimic(tmp_path / "b.hdf5", cfg)
    assert counts == {"direct_operator_1": 3, "axis_operator_2": 3}
    a = import_robomimic(
        tmp_path / "a.hdf5", obs_keys=["agent_pos", "goal_pos"], operators_from_masks="*_operator_*"
    )
    b = import_robomimic(
        tmp_path / "b.hdf5", obs_keys=["agent_pos", "goal_pos"], operators_from_masks="*_operator_*"
    )
    np.testing.assert_array_equal(a.obs, b.obs)
    np.testing.assert_array_equal(a.action, b.action)
    assert a.success.all() and np.abs(a.action).max() <= 1.0
    with h5py.File(tmp_path / "a.hdf5", "r") as f:
        assert json.loads(f["data"].attrs["env_args"])["env_kwargs"]["synthetic"] is True
    # every demo ends within the goal radius: last obs + 0.05 * last action reaches the goal
    for ep in a.episodes():
        pos, goal = ep["obs"][-1, :2], ep["obs"][-1, 2:]
        end = np.clip(pos + 0.05 * ep["action"][-1], -1, 1)
        assert np.linalg.norm(goal - end) < 0.05
    # axis-style demos move along x first: their first action's y component is only noise
    axis = a.select_operators(["axis_operator_2"]).episodes()
    assert all(abs(ep["action"][0, 1]) < 0.5 for ep in axis)
    path = tmp_path / "d.parquet"
    from elicit_jax.data.demos import write_demos

    write_demos(path, a)
    assert read_demos(path).n_episodes == 6
