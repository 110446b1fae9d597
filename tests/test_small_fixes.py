"""Smaller things a new user hit: folder vs file errors, one bad episode blocking an import,
success that was assumed, single-seed tables, identical trainings in one pipeline run."""

import io
import json

import numpy as np
import pandas as pd
from fixtures_data import invoke, lerobot_episode, write_lerobot_v21, write_robomimic
from rich.console import Console

from elicit_jax.data.demos import from_episodes, read_demos, write_demos
from elicit_jax.errors import ElicitError


def test_a_folder_where_a_file_is_expected(tmp_path):
    folder = tmp_path / "folder"  # (an output inside the input folder would be refused first)
    folder.mkdir()
    r = invoke("import", folder, "--format", "npz", "-o", tmp_path / "d.parquet")
    assert "is a folder, not a .npz file" in str(r.exception)
    r = invoke("import", folder, "--format", "robomimic", "-o", tmp_path / "d.parquet")
    assert "is a folder, not an HDF5 file" in str(r.exception)
    f = tmp_path / "x.txt"
    f.write_text("x")
    r = invoke("import", f, "--format", "lerobot", "-o", tmp_path / "d.parquet")
    assert "is a file, not a LeRobot dataset folder" in str(r.exception)


def _robomimic_with_a_nan(tmp_path):
    rng = np.random.default_rng(0)
    demos = {}
    for i in range(4):
        t = 10
        act = rng.uniform(-1, 1, size=(t, 2))
        if i == 2:
            act[4, 1] = np.nan
        demos[f"demo_{i}"] = {
            "actions": act,
            "rewards": np.r_[np.zeros(t - 1), 1.0],
            "obs/robot0_eef_pos": rng.normal(size=(t, 3)),
            "obs/robot0_eef_quat": rng.normal(size=(t, 4)),
            "obs/robot0_gripper_qpos": rng.normal(size=(t, 2)),
            "obs/object": rng.normal(size=(t, 5)),
        }
    path = tmp_path / "nan.hdf5"
    write_robomimic(path, demos)
    return path


def test_one_bad_episode_can_be_skipped_and_is_listed(tmp_path):
    src = _robomimic_with_a_nan(tmp_path)
    out = tmp_path / "d.parquet"
    r = invoke("import", src, "-o", out)
    assert isinstance(r.exception, ElicitError) and "non-finite action[1]" in str(r.exception)
    assert "(demo_2)" in str(r.exception) and not out.exists()
    r = invoke("import", src, "-o", out, "--skip-bad-episodes")
    assert r.exit_code == 0, r.output
    assert "skipped 1 of 4 episodes (demo_2: non-finite action at step 4)" in r.output
    d = read_demos(out)
    names = sorted({str(n) for n in d.extra["source_episode"]})
    assert names == ["demo_0", "demo_1", "demo_3"]
    assert d.provenance["skipped_episodes"] == [
        {"episode": 2, "source_episode": "demo_2", "reason": "non-finite action at step 4"}
    ]


def test_assumed_success_shows_as_unknown(tmp_path):
    rng = np.random.default_rng(0)
    import pyarrow.parquet as pq

    root = tmp_path / "le"
    write_lerobot_v21(root, [lerobot_episode(rng, i, 8) for i in range(3)], ["task"])
    for f in root.glob("data/*/*.parquet"):  # a dataset that never recorded success
        pq.write_table(pq.read_table(f).drop_columns(["next.success"]), f)
    out = tmp_path / "d.parquet"
    r = invoke("import", root, "-o", out)
    assert r.exit_code == 0, r.output
    assert "unknown" in r.output and "100%" not in r.output
    info = invoke("info", out)
    assert "unknown" in info.output and "100.0%" not in info.output


def test_single_seed_evaluation_table_shows_no_spread():
    from elicit_jax.cli.sim_cmds import print_summary

    summary = pd.DataFrame(
        [
            {"policy": "a", "checkpoint": "best", "n_seeds": 1, "success_mean": 78.0,
             "success_std": 0.0, "mean_length": 50.0, "unstable": 0},
            {"policy": "b", "checkpoint": "best", "n_seeds": 3, "success_mean": 80.0,
             "success_std": 4.0, "mean_length": 50.0, "unstable": 0},
        ]
    )  # fmt: skip
    buf = io.StringIO()
    print_summary(Console(file=buf, width=120), summary)
    text = buf.getvalue()
    assert "78.0 (–)" in text and "(0.0)" not in text and "80.0 (4.0)" in text


def test_identical_trainings_in_a_pipeline_are_reused(tmp_path):
    from elicit_jax.pipeline.graph import Stage
    from elicit_jax.pipeline.runner import StageContext
    from elicit_jax.pipeline.stages import train_stage
    from elicit_jax.policy.config import TrainConfig

    rng = np.random.default_rng(0)
    eps = [
        {"obs": rng.normal(size=(12, 3)), "action": rng.uniform(-1, 1, size=(12, 2))}
        for _ in range(4)
    ]
    write_demos(tmp_path / "base.parquet", from_episodes(eps, operators="base"))
    empty = tmp_path / "filtered-nothing-kept"  # a filter stage output that kept nothing
    empty.mkdir()
    cfg = TrainConfig(
        ensemble_size=2, hidden=(8,), epochs=2, checkpoint_every=2, progress_every=1,
        seeds=(0,), batch_size=16,
    )  # fmt: skip
    console = Console(file=io.StringIO())

    def ctx(name, inputs):
        stage = Stage(id=f"train/{name}", kind="train", output=f"policies/{name}",
                      config={"train": cfg.to_dict()})  # fmt: skip
        return StageContext(stage, tmp_path, tmp_path / stage.output, inputs, console)

    train_stage(ctx("base", {"demos0": tmp_path / "base.parquet"}))
    train_stage(ctx("filtered", {"demos0": tmp_path / "base.parquet", "demos1": empty}))
    assert "reused the identical training run base" in console.file.getvalue()
    a = np.load(tmp_path / "policies/base/seed0/params/best.npz")
    b = np.load(tmp_path / "policies/filtered/seed0/params/best.npz")
    assert all(np.array_equal(a[k], b[k]) for k in a.files)
    header = json.loads((tmp_path / "policies/filtered/artifact.json").read_text())
    assert header["reused_from"] == "policies/base"
    assert set(header["inputs"]) == {"demos0"}
    # other data: trained, not reused
    write_demos(tmp_path / "other.parquet", from_episodes(eps[:3], operators="base"))
    train_stage(ctx("other", {"demos0": tmp_path / "other.parquet"}))
    assert "reused_from" not in json.loads((tmp_path / "policies/other/artifact.json").read_text())
