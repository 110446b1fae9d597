"""A new user's walk, through the CLI exactly as docs/own-data.md gives it, on the file the
doc runs on (``make-example``, whose operators' demos alternate): import → split → train →
score → fit → filter → hand back. The doc's
commands are read from the doc itself, so a changed doc changes the walk. The import
checks also run on a file shaped like real teleoperation (non-default obs keys, two constant
action dims, a ±1 gripper: :func:`fixtures_data.own_robomimic_file`)."""

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from fixtures_data import cli_ok, invoke, own_robomimic_file

from elicit_jax.compat.score_file import read_scores
from elicit_jax.data.demos import read_demos

DOC = Path(__file__).resolve().parents[1] / "docs" / "own-data.md"


def doc_commands() -> list[list[str]]:
    """Every ``elicit-jax`` command of the doc's walk (up to "Handing the data back"), split
    as a shell would (comments and line continuations handled)."""
    text = DOC.read_text().split("## Handing the data back")[0]
    out = []
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        for line in block.replace("\\\n", " ").splitlines():
            words = shlex.split(line, comments=True)
            if words and words[0] == "elicit-jax":
                out.append(words[1:])
    return out


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    import os

    d = tmp_path_factory.mktemp("own-data")
    out = {"dir": d, "src": d / "teleop.hdf5", "outputs": {}}
    cwd = os.getcwd()
    os.chdir(d)  # the doc's relative paths
    try:
        for args in doc_commands():
            out["outputs"][" ".join(args[:2])] = cli_ok(*args).output
    finally:
        os.chdir(cwd)
    return out


def test_the_doc_walk_is_the_one_tested():
    cmds = [" ".join(c[:1]) for c in doc_commands()]
    assert cmds == ["make-example", "info", "import", "demos", "demos", "demos", "train",
                    "score", "fit-thresholds", "map", "filter"]  # fmt: skip


def test_import_says_what_it_needs_and_warns_about_the_actions(tmp_path):
    src = own_robomimic_file(tmp_path / "teleop.hdf5")
    info = cli_ok("info", src).output
    assert "eef_pos" in info and "op_alt" in info
    error = str(invoke("import", src, "-o", tmp_path / "x.parquet").exception)
    assert "has no 'robot0_eef_pos'" in error
    assert "choose keys with --obs-keys" in error
    out = cli_ok(
        "import", src, "--obs-keys", "eef_pos,gripper_qpos,object_pose",
        "--operators-from-masks", "op_*", "-o", tmp_path / "all.parquet",
    ).output  # fmt: skip
    assert "action dims [3, 4] are constant" in out
    assert "action dim 6 varies" in out
    all_demos = read_demos(tmp_path / "all.parquet")
    assert [f.name for f in all_demos.obs_fields] == ["eef_pos", "gripper_qpos", "object_pose"]
    assert sorted(set(all_demos.operator)) == ["op_alt", "op_base"]


def test_split_keeps_ids_and_source_names(walk):
    held = read_demos(walk["dir"] / "heldout.parquet")
    base = read_demos(walk["dir"] / "base.parquet")
    assert held.episode_ids.tolist() == [0, 2, 4, 6, 8]  # the ids step 5 names
    assert base.episode_ids.tolist() == list(range(10, 50, 2))
    assert set(held.operator) == set(base.operator) == {"direct_operator_1"}
    assert base.extra["source_episode"][0] == "demo_10"


def test_scores_fit_and_filter_separate_the_operators(walk):
    d = walk["dir"]
    header, s = read_scores(d / "scores.parquet")
    assert header["config"]["action_scale"] == "std"
    ops = s["operator"].astype(str)
    direct, axis = ops == "direct_operator_1", ops == "axis_operator_2"
    assert s["likelihood"][axis].mean() > 3 * s["likelihood"][direct].mean()
    t = json.loads((d / "thresholds.json").read_text())
    rep = t["report"]
    assert rep["balanced_accuracy"] > 0.8
    assert rep["trust"]["trustworthy"], rep["trust"]["problems"]
    # the walk gets the training-data checks by default: the 20 demos runs/base was trained
    # on are found, by content, among the scored ones; nothing is left unchecked
    assert rep["trust"]["unchecked"] == []
    assert rep["training_check"]["demos"] == 20
    assert "scoring policy's training demos rejected" in walk["outputs"]["fit-thresholds --scores"]
    assert rep["per_operator"]["direct_operator_1"]["rejected_episodes"] <= 2
    assert rep["per_operator"]["axis_operator_2"]["rejected_episodes"] >= 15
    kept = read_demos(d / "filtered.parquet")
    assert (kept.operator == "direct_operator_1").sum() > (kept.operator == "axis_operator_2").sum()
    assert (d / "filtered.dropped.parquet").exists() and (d / "map.html").stat().st_size > 1000
    names = {str(n) for n in kept.extra["source_episode"]}
    assert len({f"demo_{i}" for i in range(0, 10, 2)} & names) >= 4  # the held-out ones
    assert np.isfinite(s["novelty"]).all()


def test_step_7_hands_the_result_back_directly_and_across_a_lerobot_leg(walk):
    """The README's step 7 on the same file: a robomimic filter key in a copy of the file,
    and the same through a LeRobot dataset (its import still names the demos demo_N, so the
    mask goes back into the original file, and a new robomimic file keeps its env_args)."""
    import h5py

    d, src = walk["dir"], walk["src"]
    kept = sorted(
        {str(n) for n in read_demos(d / "filtered.parquet").extra["source_episode"]},
        key=lambda n: int(n[5:]),
    )

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
    assert sorted(set(back.operator)) == sorted(set(read_demos(d / "filtered.parquet").operator))
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
