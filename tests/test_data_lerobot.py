"""LeRobot folders v2.1 and v3.0: import, validation errors, export of an episode selection."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from fixtures_data import CAMERA, lerobot_episode, write_lerobot_v21, write_lerobot_v30

from elicit_jax.data.demos import SOURCE_EPISODE
from elicit_jax.data.lerobot import import_lerobot
from elicit_jax.data.lerobot_export import export_lerobot
from elicit_jax.errors import ElicitError

TASKS = ["pick the cube", "stack the cube"]


def _episodes(seed=0, n=5):
    rng = np.random.default_rng(seed)
    eps = [lerobot_episode(rng, i, 4 + i, success=i != 2) for i in range(n)]
    eps[3]["task_index"] = 1
    return eps


@pytest.fixture(params=["v2.1", "v3.0"])
def dataset(request, tmp_path):
    eps = _episodes()
    writer = write_lerobot_v21 if request.param == "v2.1" else write_lerobot_v30
    return writer(tmp_path / f"ds-{request.param}", eps, TASKS), eps


def test_import_each_layout(dataset):
    root, eps = dataset
    demos = import_lerobot(root, operator="op1")
    # lengths 4, 5, 6, 7, 8 -> 30 frames
    assert demos.n_episodes == 5 and demos.n_steps == 30
    for (e, s, stop), ep in zip(demos.episode_bounds(), eps, strict=True):
        np.testing.assert_allclose(demos.obs[s:stop], ep["state"], rtol=1e-6)
        np.testing.assert_allclose(demos.action[s:stop], ep["action"], rtol=1e-6)
        assert demos.extra[SOURCE_EPISODE][s] == str(e)
        assert bool(demos.success[s]) == (e != 2)
    assert demos.task == "pick the cube | stack the cube"
    assert [(f.name, f.start, f.stop) for f in demos.obs_fields] == [("observation.state", 0, 6)]
    # actions are degrees-like: bounds come from the data, per dimension
    all_actions = np.concatenate([ep["action"] for ep in eps])
    np.testing.assert_allclose(demos.action_high, all_actions.max(0), rtol=1e-6)
    assert demos.provenance["codebase_version"] == root.name.split("-")[1]
    assert set(demos.operator) == {"op1"}
    sub = import_lerobot(root, episodes=[3, 1])
    assert list(dict.fromkeys(sub.extra[SOURCE_EPISODE])) == ["1", "3"]


@pytest.mark.parametrize("version", ["v2.1", "v3.0"])
def test_export_selection_round_trip(dataset, tmp_path, version):
    root, eps = dataset
    out = tmp_path / f"out-{version}"
    written = export_lerobot(root, out, [4, 1, 3], version=version, header={"kind": "export"})
    assert written["source_episodes"] == [1, 3, 4] and written["version"] == version
    info = json.loads((out / "meta" / "info.json").read_text())
    # kept episodes have 5, 7 and 8 frames
    assert info["codebase_version"] == version and info["total_episodes"] == 3
    assert info["total_frames"] == 20 and info["splits"] == {"train": "0:3"}
    assert json.loads((out / "artifact.json").read_text())["kind"] == "export"
    back = import_lerobot(out)
    assert back.extra[SOURCE_EPISODE][[0, 5, 12]].tolist() == ["0", "1", "2"]
    np.testing.assert_allclose(back.obs[5:12], eps[3]["state"], rtol=1e-6)
    assert back.task == "pick the cube | stack the cube"
    if version == "v2.1":
        rows = [json.loads(x) for x in (out / "meta/episodes.jsonl").read_text().splitlines()]
        assert [r["length"] for r in rows] == [5, 7, 8]
        assert rows[1]["tasks"] == ["stack the cube"]
        stats = [
            json.loads(x) for x in (out / "meta/episodes_stats.jsonl").read_text().splitlines()
        ]
        state = stats[1]["stats"]["observation.state"]
        np.testing.assert_allclose(state["mean"], eps[3]["state"].mean(0), rtol=1e-5)
        assert state["count"] == [7] and "q99" in state
        frames = pq.read_table(out / "data/chunk-000/episode_000002.parquet")
    else:
        meta = pq.read_table(out / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
        assert [(m["dataset_from_index"], m["dataset_to_index"]) for m in meta] == [
            (0, 5),
            (5, 12),
            (12, 20),
        ]
        np.testing.assert_allclose(
            meta[1]["stats/observation.state/max"], eps[3]["state"].max(0), rtol=1e-6
        )
        tasks = pd.read_parquet(out / "meta/tasks.parquet")
        assert tasks.loc["stack the cube", "task_index"] == 1
        frames = pq.read_table(out / "data/chunk-000/file-000.parquet").slice(12, 8)
    # renumbered: episode_index 2 (source 4), global index 12..19, frame_index 0..7
    assert set(frames.column("episode_index").to_pylist()) == {2}
    assert frames.column("index").to_pylist() == list(range(12, 20))
    assert frames.column("frame_index").to_pylist() == list(range(8))
    assert "next.done" in frames.column_names  # other columns are kept


def _break(root, what):
    info_path = root / "meta" / "info.json"
    info = json.loads(info_path.read_text())
    if what == "version":
        info["codebase_version"] = "v1.6"
    elif what == "feature":
        del info["features"]["observation.state"]
    info_path.write_text(json.dumps(info))


@pytest.mark.parametrize(
    "what, message",
    [
        ("version", "codebase_version 'v1.6' is not supported"),
        ("feature", "meta/info.json has no feature 'observation.state'"),
    ],
)
def test_metadata_errors(dataset, what, message):
    root, _ = dataset
    _break(root, what)
    with pytest.raises(ElicitError) as err:
        import_lerobot(root)
    assert str(err.value).startswith(f"{root}: ") and message in str(err.value)


def test_frame_errors_v21(tmp_path):
    eps = _episodes()
    root = write_lerobot_v21(tmp_path / "ds", eps, TASKS)
    path = root / "data/chunk-000/episode_000002.parquet"
    table = pq.read_table(path)
    pq.write_table(table.slice(0, 5), path)  # episodes.jsonl still says 6 frames
    with pytest.raises(ElicitError, match="episode 2: metadata says 6 frames, data has 5"):
        import_lerobot(root)
    frames = table.column("frame_index").to_pylist()
    frames[3] = 9
    pq.write_table(
        table.set_column(
            table.column_names.index("frame_index"),
            "frame_index",
            __import__("pyarrow").array(frames),
        ),
        path,
    )
    with pytest.raises(ElicitError) as err:
        import_lerobot(root)
    assert str(err.value) == f"{path}: episode 2: frame_index must run 0..5, found 9 at frame 3"
    path.unlink()
    with pytest.raises(ElicitError, match="missing data file"):
        import_lerobot(root)


def test_frame_errors_v30(tmp_path):
    eps = _episodes()
    eps[1]["state"][2, 4] = np.nan
    root = write_lerobot_v30(tmp_path / "ds", eps, TASKS)
    with pytest.raises(ElicitError) as err:
        import_lerobot(root)
    assert str(err.value) == f"{root}: non-finite obs[4] value at episode 1 (1), step 2"
    with pytest.raises(ElicitError, match="has no episode 9"):
        import_lerobot(root, episodes=[9])


def test_export_refuses_self_and_unknown_versions(dataset, tmp_path):
    root, _ = dataset
    with pytest.raises(ElicitError, match="output must differ"):
        export_lerobot(root, root, [0])
    with pytest.raises(ElicitError, match=r"cannot write LeRobot codebase version 'v2\.0'"):
        export_lerobot(root, tmp_path / "o", [0], version="v2.0")
    with pytest.raises(ElicitError, match="not a LeRobot dataset folder"):
        import_lerobot(tmp_path / "nowhere")
    # the default is v3.0 whatever the source's (LeRobot 0.4+ refuses v2.1), and it is said
    written = export_lerobot(root, tmp_path / "d", [0])
    info = json.loads((tmp_path / "d/meta/info.json").read_text())
    assert written["version"] == info["codebase_version"] == "v3.0"
    assert (tmp_path / "d/meta/tasks.parquet").is_file()
    assert not (tmp_path / "d/meta/episodes.jsonl").exists()
    src = root.name.split("-")[1]
    assert any(f"the source is {src}" in n for n in written["notes"]) == (src == "v2.1")
    # v2.1 only when asked, with the command that converts it for today's LeRobot
    old = export_lerobot(root, tmp_path / "old", [0], version="v2.1")
    assert (tmp_path / "old/meta/episodes.jsonl").is_file()
    assert any(
        "LeRobot 0.4 and later refuse" in n
        and f"convert_dataset_v21_to_v30 --repo-id=REPO_ID --root={tmp_path / 'old'}" in n
        for n in old["notes"]
    )


@pytest.mark.parametrize("src, out", [("v3.0", "v3.0"), ("v2.1", "v2.1"), ("v2.1", "v3.0")])
def test_export_with_a_camera_keeps_its_stats_and_videos(tmp_path, src, out):
    eps = _episodes()
    writer = write_lerobot_v21 if src == "v2.1" else write_lerobot_v30
    root = writer(tmp_path / "src", eps, TASKS, camera=True)
    dst = tmp_path / "out"
    written = export_lerobot(root, dst, [1, 4], version=out)
    assert written["cameras"] == [CAMERA]
    # LeRobot 0.3 recorded no quantiles of cameras, and they cannot be made up: it is said
    assert bool(written["notes"]) == (src == "v2.1")
    info = json.loads((dst / "meta/info.json").read_text())
    assert info["features"][CAMERA]["dtype"] == "video"
    stats = json.loads((dst / "meta/stats.json").read_text())
    if src == "v2.1":
        src_stats = {
            json.loads(x)["episode_index"]: json.loads(x)["stats"][CAMERA]
            for x in (root / "meta/episodes_stats.jsonl").read_text().splitlines()
        }
    else:
        rows = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
        src_stats = {
            r["episode_index"]: {k: r[f"stats/{CAMERA}/{k}"] for k in ("mean", "count")}
            for r in rows
        }
    # count-weighted mean of the two episodes' per-channel means, shape (3, 1, 1)
    n1, n4 = src_stats[1]["count"][0], src_stats[4]["count"][0]
    want = (n1 * np.array(src_stats[1]["mean"]) + n4 * np.array(src_stats[4]["mean"])) / (n1 + n4)
    np.testing.assert_allclose(stats[CAMERA]["mean"], want, rtol=1e-9)
    assert np.asarray(stats[CAMERA]["mean"]).shape == (3, 1, 1)
    if out == "v3.0":
        meta = pq.read_table(dst / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
        loc = [
            (m[f"videos/{CAMERA}/file_index"], m[f"videos/{CAMERA}/from_timestamp"]) for m in meta
        ]
        if src == "v3.0":
            # episodes 1 and 4 live in files 0 (at 0.4 s) and 2 (at 0 s): both files copied whole
            assert loc == [(0, pytest.approx(0.4)), (2, 0.0)]
            for f in (0, 2):
                rel = f"videos/{CAMERA}/chunk-000/file-{f:03d}.mp4"
                assert (dst / rel).read_bytes() == (root / rel).read_bytes()
            assert not (dst / f"videos/{CAMERA}/chunk-000/file-001.mp4").exists()
        else:
            # each v2.1 episode file becomes a file of its own, starting at 0 s
            assert loc == [(0, 0.0), (1, 0.0)]
            assert meta[1][f"videos/{CAMERA}/to_timestamp"] == pytest.approx(0.8)
            got = (dst / f"videos/{CAMERA}/chunk-000/file-001.mp4").read_bytes()
            assert got == (root / f"videos/chunk-000/{CAMERA}/episode_000004.mp4").read_bytes()
    else:
        got = (dst / f"videos/chunk-000/{CAMERA}/episode_000001.mp4").read_bytes()
        assert got == (root / f"videos/chunk-000/{CAMERA}/episode_000004.mp4").read_bytes()
        assert info["total_videos"] == 2


def test_export_refuses_what_it_cannot_write_faithfully(tmp_path):
    eps = _episodes()
    v3 = write_lerobot_v30(tmp_path / "v3", eps, TASKS, camera=True)
    with pytest.raises(ElicitError, match=r"cannot be written as v2\.1"):
        export_lerobot(v3, tmp_path / "o", [0], version="v2.1")
    v2 = write_lerobot_v21(tmp_path / "v2", eps, TASKS, camera=True)
    lines = (v2 / "meta/episodes_stats.jsonl").read_text().splitlines()
    row = json.loads(lines[2])
    del row["stats"][CAMERA]
    lines[2] = json.dumps(row)
    (v2 / "meta/episodes_stats.jsonl").write_text("\n".join(lines) + "\n")
    with pytest.raises(ElicitError) as err:
        export_lerobot(v2, tmp_path / "o", [1, 2])
    assert f"episode 2 has no min/max/mean/std/count statistics for camera '{CAMERA}'" in str(
        err.value
    )
    assert "export an episode list" in str(err.value)
    export_lerobot(v2, tmp_path / "o", [1, 3])  # episodes that have them are fine
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_v21_chunks(tmp_path):
    eps = _episodes()
    root = write_lerobot_v21(tmp_path / "ds", eps, TASKS, chunks_size=2)
    assert (root / "data/chunk-002/episode_000004.parquet").is_file()  # 4 // 2 = chunk 2
    demos = import_lerobot(root)
    np.testing.assert_allclose(demos.obs[-8:], eps[4]["state"], rtol=1e-6)
    out = tmp_path / "out"
    export_lerobot(root, out, [0, 2, 4], version="v2.1")
    # new indices 0, 1, 2 -> chunks 0, 0, 1 with chunks_size 2
    assert (out / "data/chunk-001/episode_000002.parquet").is_file()
    assert json.loads((out / "meta/info.json").read_text())["total_chunks"] == 2
    back = import_lerobot(out)
    np.testing.assert_allclose(back.obs[-8:], eps[4]["state"], rtol=1e-6)


def test_variable_length_list_columns_read_like_fixed_ones(tmp_path):
    eps = _episodes()
    fixed = import_lerobot(write_lerobot_v30(tmp_path / "a", eps, TASKS))
    lists = import_lerobot(write_lerobot_v30(tmp_path / "b", eps, TASKS, fixed=False))
    np.testing.assert_array_equal(fixed.obs, lists.obs)
    np.testing.assert_array_equal(fixed.action, lists.action)
