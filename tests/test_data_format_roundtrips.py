"""Round trips through the real formats that must lose nothing: each episode's own task in a
new LeRobot dataset, robomimic ``env_args`` and demo names across a LeRobot leg (a mask still
goes back into the original HDF5), v3.0 by default, and operator labels kept for the episodes
that have them after LeRobot's ``resume()`` appended others.

The datasets are written by :mod:`fixtures_data` in the layouts LeRobot 0.6.x and robomimic
0.3 write, and what elicit-jax writes is checked against the names those libraries read
(``meta/tasks.parquet`` indexed by task text with a ``task_index`` column, the ``tasks`` list
of each episode's metadata row, ``task_index`` per frame, the keys of ``meta/info.json`` that
LeRobot's ``DatasetInfo`` keeps, robomimic's ``data.attrs['env_args']`` and ``mask/<key>``).
"""

from __future__ import annotations

import json
import warnings

import h5py
import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from fixtures_data import (
    LEROBOT_INFO_KEYS,
    append_lerobot_v30,
    lerobot_episode,
    robomimic_demo,
    write_lerobot_v30,
    write_robomimic,
)

from elicit_jax.data.demos import DemosWarning, concat_demos, read_demos, write_demos
from elicit_jax.data.export import export_dataset
from elicit_jax.data.export_config import ExportConfig
from elicit_jax.data.lerobot import import_lerobot
from elicit_jax.data.robomimic import import_robomimic
from elicit_jax.errors import ElicitError

TASKS = ["pick the cube", "stack the cube"]
ENV_ARGS = {"env_name": "NutAssemblySquare", "type": 1, "env_kwargs": {"reward_shaping": False}}


def export(selection, fmt, out, **kw):
    return export_dataset(ExportConfig(str(selection), fmt, str(out), **kw))


def _multitask(tmp_path):
    rng = np.random.default_rng(0)
    eps = [lerobot_episode(rng, i, 3 + i) for i in range(4)]
    for ep in eps[1::2]:
        ep["task_index"] = 1
    root = write_lerobot_v30(tmp_path / "src", eps, TASKS)
    write_demos(tmp_path / "d.parquet", import_lerobot(root, operator="ann"))
    return [TASKS[ep["task_index"]] for ep in eps]


@pytest.mark.parametrize("version", ["v3.0", "v2.1"])
def test_new_lerobot_dataset_keeps_each_episodes_task(tmp_path, version):
    want = _multitask(tmp_path)
    written = export(
        tmp_path / "d.parquet", "lerobot", tmp_path / "new", fresh=True, version=version
    )
    assert written["mode"] == "new dataset"
    new = tmp_path / "new"
    info = json.loads((new / "meta/info.json").read_text())
    assert info["total_tasks"] == 2
    if version == "v3.0":  # LeRobot 0.6: tasks.parquet indexed by text; episodes' `tasks` lists
        tasks = pd.read_parquet(new / "meta/tasks.parquet")
        text_of = {int(i): str(t) for t, i in zip(tasks.index, tasks["task_index"], strict=True)}
        assert tasks.index.name == "task" and sorted(text_of.values()) == sorted(TASKS)
        rows = pq.read_table(new / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
        frames = pq.read_table(new / "data/chunk-000/file-000.parquet")
    else:  # LeRobot 0.3: tasks.jsonl, episodes.jsonl, one Parquet per episode
        lines = (new / "meta/tasks.jsonl").read_text().splitlines()
        text_of = {json.loads(x)["task_index"]: json.loads(x)["task"] for x in lines}
        rows = [json.loads(x) for x in (new / "meta/episodes.jsonl").read_text().splitlines()]
        frames = pq.read_table(sorted((new / "data").glob("chunk-*/episode_*.parquet")))
    assert [r["tasks"] for r in rows] == [[t] for t in want]
    ep, ti = (frames.column(c).to_numpy() for c in ("episode_index", "task_index"))
    assert [text_of[int(i)] for i in ti] == [want[int(e)] for e in ep]
    # and back: every frame's task text, the dataset's task naming both
    back = import_lerobot(new)
    lengths = [3, 4, 5, 6]
    assert back.extra["task"].tolist() == [
        t for t, n in zip(want, lengths, strict=True) for _ in range(n)
    ]
    assert back.task == " | ".join(TASKS)


def _robomimic_via_lerobot(tmp_path):
    """robomimic file → import → new LeRobot dataset → import: (hdf5, demos parquet)."""
    rng = np.random.default_rng(0)
    demos = {f"demo_{i}": robomimic_demo(rng, 4 + i) for i in range(6)}
    masks = {"op_a": [f"demo_{i}" for i in range(3)], "op_b": [f"demo_{i}" for i in range(3, 6)]}
    h5 = write_robomimic(tmp_path / "mh.hdf5", demos, masks)
    write_demos(tmp_path / "rm.parquet", import_robomimic(h5, operators_from_masks="op_*"))
    # drop demo_0: the LeRobot episodes' indices then differ from the demos' numbers
    export(tmp_path / "rm.parquet", "lerobot", tmp_path / "lr", fps=20, episodes=tuple(range(1, 6)))
    write_demos(tmp_path / "lr.parquet", import_lerobot(tmp_path / "lr"))
    return h5, tmp_path / "lr.parquet"


def test_env_args_survive_a_lerobot_leg(tmp_path):
    _, lr = _robomimic_via_lerobot(tmp_path)
    # kept beside the data, and one key of info.json, which LeRobot 0.6 drops on rewriting
    info = json.loads((tmp_path / "lr/meta/info.json").read_text())
    assert set(info) <= {*LEROBOT_INFO_KEYS, "elicit_jax"}
    assert read_demos(lr).provenance["env_args"] == ENV_ARGS
    del info["elicit_jax"]
    (tmp_path / "lr/meta/info.json").write_text(json.dumps(info))
    assert import_lerobot(tmp_path / "lr").provenance["env_args"] == ENV_ARGS
    summary = export(lr, "robomimic", tmp_path / "back.hdf5")
    with h5py.File(tmp_path / "back.hdf5", "r") as f:
        assert json.loads(f["data"].attrs["env_args"]) == ENV_ARGS
    assert not any("cannot instantiate" in n for n in summary["notes"])


def test_demo_names_survive_a_lerobot_leg_and_a_mask_goes_back(tmp_path):
    h5, lr = _robomimic_via_lerobot(tmp_path)
    demos = read_demos(lr)
    names = [str(demos.extra["source_episode"][s]) for _, s, _ in demos.episode_bounds()]
    assert names == [f"demo_{i}" for i in range(1, 6)]
    assert demos.operator[demos.extra["source_episode"] == "demo_4"][0] == "op_b"
    assert demos.provenance["origin"]["source"] == str(h5.resolve())
    # a mask of two of them back into the original file, the names it lists checked there
    summary = export(lr, "robomimic", tmp_path / "masked.hdf5", mask_key="kept", episodes=(1, 3))
    assert summary["demos"] == ["demo_2", "demo_4"]
    with h5py.File(tmp_path / "masked.hdf5", "r") as f:
        assert [x.decode() for x in f["mask/kept"][:]] == ["demo_2", "demo_4"]
    # the LeRobot side still maps to its own episode indices: an episode list, a selection
    export(lr, "lerobot", tmp_path / "sel.json", episodes=(1, 3))
    assert json.loads((tmp_path / "sel.json").read_text())["source_episodes"] == [1, 3]
    listed = export(tmp_path / "sel.json", "robomimic", tmp_path / "m1.hdf5", mask_key="kept")
    assert listed["demos"] == ["demo_2", "demo_4"]  # the list maps back to the HDF5 too
    sub = export(lr, "lerobot", tmp_path / "sub", episodes=(1, 3))
    assert sub["source_episodes"] == [1, 3]
    again = import_lerobot(tmp_path / "sub")
    assert sorted(set(again.extra["source_episode"])) == ["demo_2", "demo_4"]
    assert again.provenance["env_args"] == ENV_ARGS
    # a changed HDF5 demo is still caught through the recorded hashes
    with h5py.File(h5, "r+") as f:
        f["data/demo_4/actions"][0, 0] += 0.5
    with pytest.raises(ElicitError, match="episode demo_4 differs from the one imported"):
        export(lr, "robomimic", tmp_path / "m2.hdf5", mask_key="kept", episodes=(3,))


def test_operator_labels_kept_after_lerobot_resume_appends_episodes(tmp_path):
    rng = np.random.default_rng(0)
    root = write_lerobot_v30(
        tmp_path / "src", [lerobot_episode(rng, i, 4) for i in range(4)], ["t"]
    )
    parts = [
        import_lerobot(root, operator=op, episodes=eps, action_bounds=(-90.0, 90.0))
        for op, eps in (("ann", [0, 1]), ("bob", [2, 3]))
    ]
    write_demos(tmp_path / "d.parquet", concat_demos(parts))
    export(tmp_path / "d.parquet", "lerobot", tmp_path / "lr", fresh=True)
    new = [lerobot_episode(rng, i, 5) for i in (4, 5)]
    append_lerobot_v30(tmp_path / "lr", new, "t")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DemosWarning)
        back = import_lerobot(tmp_path / "lr")
    ops = [str(back.operator[s]) for _, s, _ in back.episode_bounds()]
    assert ops == ["ann", "ann", "bob", "bob", "unknown", "unknown"]
    said = [str(w.message) for w in caught if issubclass(w.category, DemosWarning)]
    assert len(said) == 1 and "2 episodes (4, 5) match no episode it records" in said[0]
    np.testing.assert_allclose(back.obs[-5:], new[1]["state"], rtol=1e-6)
    # the record still gives the declared action bounds, whatever the appended actions span
    assert back.provenance["labels_from"] == "artifact.json (elicit-jax export)"
    assert (back.action_low, back.action_high) == (-90.0, 90.0)
    assert back.provenance["unlabelled_episodes"] == [4, 5]
    # an episode whose frames are not the recorded ones is not trusted either
    record = json.loads((tmp_path / "lr/artifact.json").read_text())
    record["episodes"][1]["sha256"] = "0" * 64
    (tmp_path / "lr/artifact.json").write_text(json.dumps(record))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DemosWarning)
        again = import_lerobot(tmp_path / "lr")
    said = " ".join(str(w.message) for w in caught)
    assert "3 episodes (1, 4, 5) match no episode it records" in said
    assert [str(again.operator[s]) for _, s, _ in again.episode_bounds()][:3] == [
        "ann",
        "unknown",
        "bob",
    ]
    # a record from before the hashes: matched by index and length, appended ones unknown
    for e in record["episodes"]:
        del e["sha256"]
    (tmp_path / "lr/artifact.json").write_text(json.dumps(record))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DemosWarning)
        old = import_lerobot(tmp_path / "lr")
    assert [str(old.operator[s]) for _, s, _ in old.episode_bounds()] == ops
    assert "2 episodes (4, 5) were added after the export" in str(caught[0].message)
    # and a record that is not one is a one-line error naming it
    record["episodes"][0] = {"length": 4}
    (tmp_path / "lr/artifact.json").write_text(json.dumps(record))
    with pytest.raises(ElicitError, match=r"lr/artifact.json: malformed export record \(KeyError"):
        import_lerobot(tmp_path / "lr")


def _lerobot_rewrite(root, keep, *, version="v3.0"):
    """Rewrite a LeRobot folder in place as LeRobot's own tools leave it: ``delete_episodes``
    (the kept episodes renumbered 0..k-1, frames unchanged, a new ``info.json`` holding only
    the keys LeRobot knows), or, with all episodes kept and ``version`` v3.0 from v2.1, the
    v2.1 -> v3.0 converter (the old folder moved to ``<name>_old``, ``info.json`` carried
    with every key it had). Returns the new folder."""
    import shutil

    from elicit_jax.data.lerobot_export import export_lerobot

    info = json.loads((root / "meta/info.json").read_text())
    new = root.parent / f"{root.name}_new"
    export_lerobot(root, new, keep, version=version)
    written = json.loads((new / "meta/info.json").read_text())
    if info["codebase_version"] == version:  # delete_episodes: LeRobotDatasetMetadata.create
        written = {k: v for k, v in written.items() if k in LEROBOT_INFO_KEYS}
        shutil.rmtree(root)
    else:  # the converter: convert_info() rewrites the loaded dict, extra keys and all
        written = {**info, **{k: v for k, v in written.items() if k in LEROBOT_INFO_KEYS}}
        shutil.move(root, root.parent / f"{root.name}_old")
    (new / "meta/info.json").write_text(json.dumps(written, indent=4))
    shutil.move(new, root)
    return root


def _ten_demos_via_lerobot(tmp_path, version="v3.0"):
    """robomimic demo_0..demo_9 (demo_9 as long as demo_7) → import → new LeRobot folder."""
    rng = np.random.default_rng(3)
    lengths = [4 + i for i in range(9)] + [11]
    demos = {f"demo_{i}": robomimic_demo(rng, t) for i, t in enumerate(lengths)}
    masks = {"op_a": [f"demo_{i}" for i in range(5)], "op_b": [f"demo_{i}" for i in range(5, 10)]}
    h5 = write_robomimic(tmp_path / "mh.hdf5", demos, masks)
    write_demos(tmp_path / "rm.parquet", import_robomimic(h5, operators_from_masks="op_*"))
    export(tmp_path / "rm.parquet", "lerobot", tmp_path / "lr", fps=20, version=version)
    return h5, tmp_path / "lr"


def _names_ops(demos):
    bounds = demos.episode_bounds()
    return [str(demos.extra["source_episode"][s]) for _, s, _ in bounds], [
        str(demos.operator[s]) for _, s, _ in bounds
    ]


def test_labels_follow_the_frames_after_lerobot_delete_episodes(tmp_path):
    _, lr = _ten_demos_via_lerobot(tmp_path)
    record = (lr / "artifact.json").read_text()
    _lerobot_rewrite(lr, list(range(2, 10)))  # delete_episodes([0, 1]) in place
    (lr / "artifact.json").write_text(record)  # and the user copies the record back
    back = import_lerobot(lr)
    names, ops = _names_ops(back)
    assert names == [f"demo_{i}" for i in range(2, 10)]  # episode 7 is demo_9, not demo_7
    assert ops == ["op_a"] * 3 + ["op_b"] * 5
    write_demos(tmp_path / "back.parquet", back)
    summary = export(tmp_path / "back.parquet", "robomimic", tmp_path / "m.hdf5", mask_key="k",
                     episodes=(7,))  # fmt: skip
    assert summary["demos"] == ["demo_9"]
    with h5py.File(tmp_path / "m.hdf5", "r") as f:
        assert [x.decode() for x in f["mask/k"][:]] == ["demo_9"]
    # a record without hashes (an older elicit-jax) cannot be matched: refused, one line
    old = json.loads(record)
    for e in old["episodes"]:
        del e["sha256"]
    (lr / "artifact.json").write_text(json.dumps(old))
    with pytest.raises(ElicitError, match=r"lr/artifact.json: records episode 0 with 4 frames.*"
                       r"no content hashes") as e:  # fmt: skip
        import_lerobot(lr)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("keep_info_key", [True, False])
def test_labels_survive_lerobots_v21_to_v30_converter(tmp_path, keep_info_key):
    _, lr = _ten_demos_via_lerobot(tmp_path, version="v2.1")
    _lerobot_rewrite(lr, list(range(10)), version="v3.0")
    assert not (lr / "artifact.json").exists() and (tmp_path / "lr_old/artifact.json").exists()
    if not keep_info_key:  # a LeRobot that rewrote info.json with only the keys it knows
        info = json.loads((lr / "meta/info.json").read_text())
        (lr / "meta/info.json").write_text(json.dumps({k: info[k] for k in LEROBOT_INFO_KEYS
                                                       if k in info}))  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DemosWarning)
        back = import_lerobot(lr)
    said = [str(w.message) for w in caught if issubclass(w.category, DemosWarning)]
    names, ops = _names_ops(back)
    if keep_info_key:
        assert not said
        assert names == [f"demo_{i}" for i in range(10)]
        assert ops == ["op_a"] * 5 + ["op_b"] * 5
        assert back.provenance["env_args"] == ENV_ARGS
        assert back.provenance["labels_from"] == "meta/info.json (elicit-jax export)"
    else:  # nothing left in the folder: said loudly, naming where the record went
        assert len(said) == 1 and "lr_old/artifact.json does" in said[0]
        assert "copy that artifact.json into" in said[0]
        assert set(ops) == {"unknown"}


def test_own_columns_are_not_lerobot_features(tmp_path):
    """Filter's pre_filter_* columns (and concat's part) are kept in the record, not as
    features: LeRobot's add_frame after resume() asks for every feature of info.json."""
    import dataclasses

    _, lr = _ten_demos_via_lerobot(tmp_path)
    demos = import_lerobot(lr)
    ep, step = demos.episode.astype(np.int64), demos.step.astype(np.int32)
    gap = np.where(demos.episode % 2 == 0, step + (step >= 2), step)  # pair 2 dropped in some
    demos = dataclasses.replace(
        demos, extra={**demos.extra, "pre_filter_episode": ep + 3, "pre_filter_step": gap}
    )
    write_demos(tmp_path / "f.parquet", demos)
    export(tmp_path / "f.parquet", "lerobot", tmp_path / "out", fresh=True, fps=20)
    info = json.loads((tmp_path / "out/meta/info.json").read_text())
    assert set(info["features"]) == {
        "observation.state", "action", "next.reward", "next.done", "next.success",
        "timestamp", "frame_index", "episode_index", "index", "task_index",
    }  # fmt: skip
    frames = pq.read_table(tmp_path / "out/data/chunk-000/file-000.parquet")
    assert "pre_filter_step" not in frames.column_names
    back = import_lerobot(tmp_path / "out")
    np.testing.assert_array_equal(
        back.extra["pre_filter_episode"], demos.extra["pre_filter_episode"]
    )
    np.testing.assert_array_equal(back.extra["pre_filter_step"], demos.extra["pre_filter_step"])
    assert back.extra["pre_filter_step"].dtype == np.int32
