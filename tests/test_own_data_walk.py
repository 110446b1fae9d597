"""A new user's walk with their own robomimic file, through the CLI exactly as docs/own-data.md
gives it: import with --obs-keys → split → train → score → fit →
filter. The file has non-default obs keys, two constant action dims, a ±1 gripper and two
operator mask keys (:func:`fixtures_data.own_robomimic_file`)."""

import json

import numpy as np
import pytest
from fixtures_data import cli_ok, invoke, own_robomimic_file

from elicit_jax.compat.score_file import read_scores
from elicit_jax.data.demos import read_demos


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    d = tmp_path_factory.mktemp("own-data")
    src = own_robomimic_file(d / "teleop.hdf5")
    out = {"dir": d, "src": src}
    # 1. look, then import with the file's own obs keys and operators from its mask keys
    out["info"] = cli_ok("info", src).output
    r = invoke("import", src, "-o", d / "x.parquet")
    out["default_keys_error"] = str(r.exception)
    out["import"] = cli_ok(
        "import", src, "--obs-keys", "eef_pos,gripper_qpos,object_pose",
        "--operators-from-masks", "op_*", "-o", d / "all.parquet",
    ).output  # fmt: skip
    # 2. split: three base demos held out for the threshold fit, the rest trains
    cli_ok("demos", "list", d / "all.parquet")
    cli_ok("demos", "select", d / "all.parquet", "--episodes", "0-2", "-o", d / "heldout.parquet")
    cli_ok(
        "demos", "select", d / "all.parquet", "--operator", "op_base", "--exclude", "0-2",
        "-o", d / "base.parquet",
    )  # fmt: skip
    # 3. train the base policy (a small net, so the test is quick)
    out["train"] = cli_ok(
        "train", "--demos", d / "base.parquet", "--out", d / "runs/base", "--profile", "cpu",
        "--hidden", "64,64", "--epochs", "150", "--ensemble-size", "3", "--batch-size", "64",
        "--checkpoint-every", "50",
    ).output  # fmt: skip
    # 4. score everything, each action dim in units of its spread (the gripper would dominate)
    out["score"] = cli_ok(
        "score", "--policy", d / "runs/base", "--demos", d / "all.parquet", "-o",
        d / "scores.parquet", "--action-scale", "std",
    ).output  # fmt: skip
    # 5. fit thresholds: held-out base demos vs the other operator
    out["fit"] = cli_ok(
        "fit-thresholds", "--scores", d / "scores.parquet", "--compatible", "episodes:0-2",
        "--incompatible", "operator:op_alt", "-o", d / "thresholds.json",
    ).output  # fmt: skip
    cli_ok(
        "map", "--scores", d / "scores.parquet", "--thresholds", d / "thresholds.json",
        "-o", d / "map.html",
    )  # fmt: skip
    # 6. filter: drop rejected demos of the new operator
    out["filter"] = cli_ok(
        "filter", "--scores", d / "scores.parquet", "--demos", d / "all.parquet",
        "--thresholds", d / "thresholds.json", "--level", "episode", "-o", d / "filtered.parquet",
    ).output  # fmt: skip
    return out


def test_import_says_what_it_needs_and_warns_about_the_actions(walk):
    assert "eef_pos" in walk["info"] and "op_alt" in walk["info"]
    assert "has no 'robot0_eef_pos'" in walk["default_keys_error"]
    assert "choose keys with --obs-keys" in walk["default_keys_error"]
    assert "action dims [3, 4] are constant" in walk["import"]
    assert "action dim 6 varies" in walk["import"]
    all_demos = read_demos(walk["dir"] / "all.parquet")
    assert [f.name for f in all_demos.obs_fields] == ["eef_pos", "gripper_qpos", "object_pose"]
    assert sorted(set(all_demos.operator)) == ["op_alt", "op_base"]


def test_split_keeps_ids_and_source_names(walk):
    held = read_demos(walk["dir"] / "heldout.parquet")
    base = read_demos(walk["dir"] / "base.parquet")
    assert held.episode_ids.tolist() == [0, 1, 2]
    assert base.episode_ids.tolist() == list(range(3, 12))
    assert base.extra["source_episode"][0] == "demo_3"


def test_scores_fit_and_filter_separate_the_operators(walk):
    d = walk["dir"]
    header, s = read_scores(d / "scores.parquet")
    assert header["config"]["action_scale"] == "std"
    # the task's preset is in raw action units: with std scaling its M is not a verdict
    # for M and accept/reject, and recorded as such (docs/thresholds.md)
    assert header["thresholds_source"].startswith("raw-unit preset")
    assert "preset square-nut (task NutAssemblySquare)" in header["thresholds_source"]
    ops = s["operator"].astype(str)
    assert s["likelihood"][ops == "op_alt"].mean() > 5 * s["likelihood"][ops == "op_base"].mean()
    t = json.loads((d / "thresholds.json").read_text())
    rep = t["report"]
    assert rep["balanced_accuracy"] == 1.0
    assert rep["trust"]["trustworthy"], rep["trust"]["problems"]
    # the walk gets the training-data checks by default: the 9 demos runs/base was trained on
    # are found, by content, among the scored ones; nothing is left unchecked
    assert rep["trust"]["unchecked"] == []
    assert rep["training_check"] == {"demos": 9, "rejected": 0, "source": "9 scored in this file"}
    assert "base policy's training demos" in walk["fit"]
    assert rep["per_operator"]["op_base"]["rejected_episodes"] == 0
    assert rep["per_operator"]["op_alt"]["rejected_episodes"] == 6
    kept = read_demos(d / "filtered.parquet")
    assert sorted(set(kept.operator)) == ["op_base"] and kept.n_episodes == 12
    assert (d / "filtered.dropped.parquet").exists() and (d / "map.html").stat().st_size > 1000
    names = {str(n) for n in kept.extra["source_episode"]}
    assert names == {f"demo_{i}" for i in range(12)}
    assert np.isfinite(s["novelty"]).all()


def test_step_7_hands_the_result_back_directly_and_across_a_lerobot_leg(walk):
    """The README's step 7 on the same file: a robomimic filter key in a copy of the file,
    and the same through a LeRobot dataset (its import still names the demos demo_N, so the
    mask goes back into the original file, and a new robomimic file keeps its env_args)."""
    import h5py

    d, src = walk["dir"], walk["src"]
    kept = [f"demo_{i}" for i in range(12)]

    def mask(path, key):
        with h5py.File(path, "r") as f:
            return sorted((x.decode() for x in f["mask"][key][:]), key=lambda n: int(n[5:]))

    out = cli_ok(
        "export", d / "filtered.parquet", "-f", "robomimic", "--mask-key", "compatible",
        "-o", d / "low_dim_compatible.hdf5",
    ).output  # fmt: skip
    assert "config.train.hdf5_filter_key=compatible" in out
    assert mask(d / "low_dim_compatible.hdf5", "compatible") == kept
    out = cli_ok(
        "export", d / "filtered.parquet", "-f", "lerobot", "--fps", "20", "-o", d / "lr"
    ).output
    assert "lerobot v3.0, new dataset" in out
    cli_ok("import", d / "lr", "-o", d / "lr.parquet")
    back = read_demos(d / "lr.parquet")
    assert sorted(set(back.operator)) == ["op_base"]
    assert sorted(set(back.extra["source_episode"]), key=lambda n: int(n[5:])) == kept
    cli_ok(
        "export", d / "lr.parquet", "-f", "robomimic", "--mask-key", "via_lerobot",
        "-o", d / "via_lerobot.hdf5",
    )  # fmt: skip
    assert mask(d / "via_lerobot.hdf5", "via_lerobot") == kept
    out = cli_ok("export", d / "lr.parquet", "-f", "robomimic", "-o", d / "new.hdf5").output
    assert "cannot instantiate" not in out
    with h5py.File(src, "r") as a, h5py.File(d / "new.hdf5", "r") as b:
        assert json.loads(b["data"].attrs["env_args"]) == json.loads(a["data"].attrs["env_args"])
