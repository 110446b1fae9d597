"""The data commands end to end through the real entry point, and the fast-start guard."""

from __future__ import annotations

import json
import subprocess
import sys

import h5py
import numpy as np
import pytest
from fixtures_data import lerobot_episode, write_lerobot_v30

from elicit_jax.data.demos import read_demos


def test_quickstart_make_example_import_info_export(cli, tmp_path):
    ex, demos, copy = tmp_path / "example.hdf5", tmp_path / "demos.parquet", tmp_path / "copy.hdf5"
    code, out, _ = cli("make-example", "-o", ex, "--demos-per-operator", 4)
    assert code == 0 and "synthetic" in out and "direct_operator_1: 4 demos" in out
    code, out, err = cli(
        "import",
        ex,
        "--format",
        "robomimic",
        "--obs-keys",
        "agent_pos,goal_pos",
        "--operators-from-masks",
        "*_operator_*",
        "-o",
        demos,
    )
    assert code == 0, err
    assert "axis_operator_2" in out and "direct_operator_1" in out
    code, out, _ = cli("info", demos)
    assert code == 0
    for text in (
        "demonstrations (schema v1)",
        "ToyReach2D (synthetic)",
        "agent_pos",
        "0:2",
        "episodes per operator",
        "success",
        "robomimic",
        str(ex.resolve()),
    ):
        assert text in out
    code, out, err = cli(
        "export",
        demos,
        "--format",
        "robomimic",
        "--mask-key",
        "kept",
        "--episodes",
        "0,2-3",
        "-o",
        copy,
    )
    assert code == 0, err
    assert "hdf5_filter_key=kept" in out
    with h5py.File(copy, "r") as f:
        assert [x.decode() for x in f["mask/kept"][:]] == ["demo_0", "demo_2", "demo_3"]
        header = json.loads(f["mask/kept"].attrs["elicit_jax"])
        assert header["kind"] == "export" and header["inputs"]["selection"]["sha256"]
    code, _, err = cli(
        "export",
        demos,
        "--format",
        "robomimic",
        "--mask-key",
        "train",
        "--source",
        ex,
        "-o",
        tmp_path / "c2.hdf5",
    )
    assert code == 1 and err.count("\n") == 1
    assert "already has mask/train; pick another --mask-key or pass --overwrite" in err
    code, out, err = cli(
        "export", demos, "-f", "robomimic", "--mask-key", "more", "--source", copy, "--in-place"
    )
    assert code == 0, err
    assert f"wrote {copy} (robomimic, mask)" in out and "in place (nothing else" in out
    with h5py.File(copy, "r") as f:
        assert len(f["mask/more"]) == 8 and len(f["mask/kept"]) == 3
    code, _, err = cli(
        "export", demos, "--format", "lerobot", "--episodes", "1", "-o", tmp_path / "sel.json"
    )
    assert code == 1 and "an episode list names episodes of a LeRobot dataset" in err
    code, _, _ = cli("export", demos, "--format", "npz", "-o", tmp_path / "d.npz")
    code, _, err = cli("import", tmp_path / "d.npz", "-o", tmp_path / "d2.parquet")
    assert code == 0, err
    a, b = read_demos(demos), read_demos(tmp_path / "d2.parquet")
    np.testing.assert_array_equal(a.obs, b.obs)
    assert a.operator.tolist() == b.operator.tolist()
    code, out, _ = cli("info", ex)
    assert "robomimic dataset (not yet imported)" in out and "direct_operator_1" in out


def test_lerobot_import_and_folder_export(cli, tmp_path):
    rng = np.random.default_rng(0)
    root = write_lerobot_v30(
        tmp_path / "ds", [lerobot_episode(rng, i, 5) for i in range(4)], ["wipe"]
    )
    demos = tmp_path / "d.parquet"
    code, _, err = cli("import", root, "-o", demos, "--operator", "ann")
    assert code == 0, err
    code, _, err = cli(
        "export",
        demos,
        "--format",
        "lerobot",
        "--episodes",
        "1,3",
        "--version",
        "v3.0",
        "-o",
        tmp_path / "out",
    )
    assert code == 0, err
    code, out, _ = cli("info", tmp_path / "out")
    assert "export" in out
    code, out, err = cli(
        "export", demos, "-f", "lerobot", "--episodes", "1,3", "-o", tmp_path / "l.json"
    )
    assert code == 0, err
    assert "load in LeRobot: import json; from lerobot.datasets.lerobot_dataset import" in out
    code, out, _ = cli("info", tmp_path / "l.json")
    assert "episode list" in out and "1, 3" in out
    code, out, _ = cli("import", tmp_path / "out", "-o", tmp_path / "e.parquet")
    assert code == 0 and read_demos(tmp_path / "e.parquet").n_episodes == 2
    code, out, _ = cli("info", root)
    assert "LeRobot dataset v3.0" in out


@pytest.mark.parametrize(
    "args, message",
    [
        (["import", "{d}/missing.hdf5", "-o", "{d}/o.parquet"], "missing.hdf5: file not found"),
        (["import", "{d}/x.txt", "-o", "{d}/o.parquet"], "x.txt: unknown dataset format '.txt'"),
        (
            ["import", "{d}/ex.hdf5", "-o", "{d}/o.parquet"],
            "data/demo_0/obs has no 'robot0_eef_pos' (available: agent_pos, goal_pos)",
        ),
        (
            [
                "import",
                "{d}/ex.hdf5",
                "--obs-keys",
                "agent_pos",
                "--filter-key",
                "nope",
                "-o",
                "{d}/o.parquet",
            ],
            "no mask/nope (available filter keys: axis_operator_2",
        ),
        (
            ["import", "{d}/ex.hdf5", "--format", "csv", "-o", "{d}/o.parquet"],
            "unknown format 'csv'",
        ),
        (
            ["import", "{d}/ex.hdf5", "--obs-keys", "agent_pos", "-o", "{d}/o.csv"],
            "o.csv: output must be a .parquet file",
        ),
        (
            ["import", "{d}/big.npz", "-o", "{d}/o.parquet"],
            "big.npz: action[0] = 2 outside bounds [-1, 1] at episode 0 (0), step 1",
        ),
        (["info", "{d}/x.txt"], "x.txt: not a readable Parquet file"),
        (
            ["export", "{d}/ex.hdf5", "--format", "npz", "-o", "{d}/o.npz"],
            "ex.hdf5: not a readable Parquet file",
        ),
    ],
)
def test_errors_are_one_line_without_traceback(cli, tmp_path, args, message):
    from elicit_jax.data.synthetic import ToyConfig, make_toy_robomimic

    make_toy_robomimic(tmp_path / "ex.hdf5", ToyConfig(demos_per_operator=1))
    (tmp_path / "x.txt").write_text("hello")
    np.savez(
        tmp_path / "big.npz",
        obs=np.zeros((3, 2)),
        act=np.array([[0.0], [2.0], [0.5]]),
        lengths=np.array([3]),
    )
    code, out, err = cli(*[a.format(d=tmp_path) for a in args])
    assert code == 1
    assert err.startswith("error: ") and err.count("\n") == 1 and message in err, err
    assert "Traceback" not in err + out
    assert not (tmp_path / "o.parquet").exists()


def test_warn_and_clip_actions_flags(cli, tmp_path):
    np.savez(
        tmp_path / "big.npz",
        obs=np.zeros((3, 2)),
        act=np.array([[0.0], [2.0], [0.5]]),
        lengths=np.array([3]),
    )
    code, _, err = cli(
        "import", tmp_path / "big.npz", "--warn-actions", "-o", tmp_path / "w.parquet"
    )
    assert code == 0 and err.startswith("warning: ") and "outside bounds" in err
    code, _, err = cli(
        "import", tmp_path / "big.npz", "--clip-actions", "-o", tmp_path / "c.parquet"
    )
    assert code == 0 and err == ""
    assert read_demos(tmp_path / "c.parquet").action[:, 0].tolist() == [0.0, 1.0, 0.5]
    code, _, err = cli(
        "import", tmp_path / "big.npz", "--action-bounds", "data", "-o", tmp_path / "d.parquet"
    )
    assert code == 0 and read_demos(tmp_path / "d.parquet").action_high == (2.0,)


def test_help_imports_no_heavy_libraries():
    code = (
        "import sys\n"
        "sys.argv = ['elicit-jax', '--help']\n"
        "from elicit_jax.cli import main\n"
        "try:\n    main()\nexcept SystemExit:\n    pass\n"
        "heavy = ('jax', 'jaxlib', 'mujoco', 'flax', 'optax', 'pandas', 'h5py', 'matplotlib')\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in heavy))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "import" in done.stdout and "make-example" in done.stdout
    assert done.stdout.strip().splitlines()[-1] == "[]"


def test_info_falls_back_to_header_fields_for_unknown_kinds(cli, tmp_path):
    from elicit_jax.artifact import make_header, write_json

    (tmp_path / "in.txt").write_text("x")
    header = make_header(
        "mystery",
        3,
        config={"lr": 0.001},
        inputs={"data": tmp_path / "in.txt"},
        seed=5,
        shape=[2, 3],
    )
    write_json(tmp_path / "m.json", header)
    code, out, _ = cli("info", tmp_path / "m.json")
    assert code == 0 and "mystery (schema v3)" in out
    assert '"lr": 0.001' in out and "shape" in out and "input data" in out and "seed" in out
