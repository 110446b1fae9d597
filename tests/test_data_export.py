"""``export`` from any demos artifact: masks checked per demo (in a copy or in place), demos
with dropped pairs or several sources, new robomimic files and LeRobot datasets that read
back bit-equal, episode lists LeRobot can filter on."""

from __future__ import annotations

import dataclasses
import json

import h5py
import numpy as np
import pytest
from fixtures_data import (
    lerobot_episode,
    robomimic_demo,
    write_lerobot_v21,
    write_lerobot_v30,
    write_robomimic,
)

from elicit_jax.data import robomimic_export
from elicit_jax.data.demos import concat_demos, read_demos, write_demos
from elicit_jax.data.export import export_dataset
from elicit_jax.data.export_config import ExportConfig
from elicit_jax.data.lerobot import import_lerobot
from elicit_jax.data.robomimic import import_robomimic
from elicit_jax.errors import ElicitError

KEYS = ("robot0_eef_pos", "robot0_eef_quat", "robot0_gripper_qpos", "object")
CORE = ("obs", "action", "reward", "episode", "step", "success")


@pytest.fixture
def mh(tmp_path):
    """A multi-operator robomimic file (demo_0..demo_7, masks per operator) and its import."""
    rng = np.random.default_rng(0)
    demos = {f"demo_{i}": robomimic_demo(rng, 4 + i) for i in range(8)}
    masks = {"op_a": [f"demo_{i}" for i in range(4)], "op_b": [f"demo_{i}" for i in range(4, 8)]}
    path = write_robomimic(tmp_path / "mh.hdf5", demos, masks)
    parquet = tmp_path / "mh.parquet"
    write_demos(parquet, import_robomimic(path, operators_from_masks="op_*"))
    return path, parquet


def export(selection, fmt, out=None, **kw):
    return export_dataset(
        ExportConfig(str(selection), fmt, None if out is None else str(out), **kw)
    )


def masks_of(path):
    with h5py.File(path, "r") as f:
        return {k: [x.decode() for x in f["mask"][k][:]] for k in f["mask"]}


def same_core(a, b):
    for k in CORE:
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k), err_msg=k)
    assert a.operator.tolist() == b.operator.tolist()
    assert (a.task, a.obs_fields, a.action_low, a.action_high) == (
        b.task,
        b.obs_fields,
        b.action_low,
        b.action_high,
    )


def test_masks_added_by_other_tools_do_not_block_export(mh, tmp_path):
    path, demos = mh
    # robomimic's split_train_val.py adds masks in place: the file's bytes change, demos don't
    with h5py.File(path, "a") as f:
        f["mask/train"] = np.array([f"demo_{i}" for i in range(7)], dtype="S")
        f["mask/valid"] = np.array(["demo_7"], dtype="S")
    copy = tmp_path / "copy.hdf5"
    export(demos, "robomimic", copy, mask_key="first", episodes=(0, 5))
    # a second mask key in the same copy, into a new copy and in place
    export(demos, "robomimic", tmp_path / "copy2.hdf5", mask_key="second", source=str(copy))
    assert set(masks_of(tmp_path / "copy2.hdf5")) == {
        "op_a",
        "op_b",
        "train",
        "valid",
        "first",
        "second",
    }
    before = robomimic_export.content_digest(copy, "mask/third")
    summary = export(
        demos, "robomimic", mask_key="third", source=str(copy), in_place=True, episodes=(1, 2)
    )
    assert summary["in_place"] and summary["out"] == str(copy)
    assert masks_of(copy)["third"] == ["demo_1", "demo_2"] and masks_of(copy)["first"] == [
        "demo_0",
        "demo_5",
    ]
    assert robomimic_export.content_digest(copy, "mask/third") == before
    # a demo whose content changed is caught; the others still export
    with h5py.File(copy, "a") as f:
        f["data/demo_2/actions"][0, 0] += 0.5
    with pytest.raises(ElicitError, match="episode demo_2 differs from the one imported"):
        export(demos, "robomimic", tmp_path / "c3.hdf5", mask_key="k", source=str(copy))
    export(
        demos, "robomimic", tmp_path / "c3.hdf5", mask_key="k", source=str(copy), episodes=(0, 1)
    )
    with pytest.raises(ElicitError, match="already exists; pass --overwrite"):
        export(
            demos, "robomimic", tmp_path / "c3.hdf5", mask_key="k2", source=str(copy), episodes=(0,)
        )


def test_in_place_refuses_when_anything_else_changed(mh, monkeypatch):
    path, demos = mh
    real = robomimic_export.edit_copy
    before = path.read_bytes()

    def write_and_touch(source, copy, datasets, needs):
        real(source, copy, datasets, needs)
        with h5py.File(copy, "a") as f:
            f["data/demo_3"].attrs["num_samples"] = 99

    monkeypatch.setattr(robomimic_export, "edit_copy", write_and_touch)
    unchanged = r"content other than mask/k changed.*the source file was not changed"
    with pytest.raises(ElicitError, match=unchanged):
        export(demos, "robomimic", mask_key="k", in_place=True)
    assert path.read_bytes() == before
    with pytest.raises(ElicitError, match="needs --format robomimic and --mask-key"):
        ExportConfig(str(demos), "robomimic", in_place=True)
    with pytest.raises(ElicitError, match="not both"):
        ExportConfig(str(demos), "robomimic", "x.hdf5", mask_key="k", in_place=True)


def _drop_pairs(demos_path, out, pair_mode, episode=5):
    """What ``filter --level pair`` writes: demos without pairs 2..4 of one episode."""
    from elicit_jax.compat.filtering import apply_drop

    demos = read_demos(demos_path)
    drop = (demos.episode == episode) & np.isin(demos.step, [2, 3, 4])
    write_demos(out, apply_drop(demos, drop, pair_mode))
    return read_demos(out)


def test_pair_filtered_demos_are_refused_as_a_mask_and_written_whole(mh, tmp_path):
    _, demos = mh
    kept = _drop_pairs(demos, tmp_path / "kept.parquet", "renumber")
    with pytest.raises(ElicitError) as err:
        export(tmp_path / "kept.parquet", "robomimic", tmp_path / "m.hdf5", mask_key="kept")
    msg = str(err.value)
    assert "episode 5 holds 6 of source episode demo_5's 9 steps" in msg
    assert "drop --mask-key to write them as a new robomimic file" in msg
    assert not (tmp_path / "m.hdf5").exists()
    # without a mask key: a new file holding exactly the kept steps
    summary = export(tmp_path / "kept.parquet", "robomimic", tmp_path / "new.hdf5")
    assert any("join steps across dropped pairs" in n for n in summary["notes"])
    back = import_robomimic(tmp_path / "new.hdf5", obs_keys=KEYS, operators_from_masks="op_a,op_b")
    same_core(back, kept)
    with h5py.File(tmp_path / "new.hdf5", "r") as f:
        g = f["data/demo_5"]
        assert g.attrs["source_episode"] == "demo_5" and g.attrs["num_samples"] == 6
        assert g["extras/pre_filter_step"][:].tolist() == [0, 1, 5, 6, 7, 8]
        assert json.loads(f["data"].attrs["env_args"])["env_name"] == "NutAssemblySquare"
        provenance = json.loads(f["data"].attrs["elicit_jax"])
        assert provenance["inputs"]["selection"]["sha256"] and provenance["notes"]
    # split mode: contiguous pieces, no jumps to warn about
    _drop_pairs(demos, tmp_path / "split.parquet", "split")
    with pytest.raises(ElicitError, match="source episode demo_5 is split over 2 episodes"):
        export(tmp_path / "split.parquet", "robomimic", tmp_path / "m.hdf5", mask_key="kept")
    summary = export(tmp_path / "split.parquet", "robomimic", tmp_path / "split.hdf5")
    assert len(summary["demos"]) == 9
    assert not any("join steps" in n for n in summary["notes"])


def test_demos_concatenated_from_one_file_export_as_a_mask(mh, tmp_path):
    path, _ = mh
    # what filter --base writes: two imports of the same file, concatenated, renumbered
    a = import_robomimic(path, filter_key="op_a", operators_from_masks="op_*")
    b = import_robomimic(path, filter_key="op_b", operators_from_masks="op_*")
    both = concat_demos([a.select_episodes([0, 1]), b.select_episodes([2])])
    assert "parts" in both.provenance
    write_demos(tmp_path / "both.parquet", both)
    summary = export(tmp_path / "both.parquet", "robomimic", tmp_path / "m.hdf5", mask_key="kept")
    assert summary["demos"] == ["demo_0", "demo_1", "demo_6"]
    # with collected demos mixed in there is no one source file to mark
    collected = dataclasses.replace(
        a.select_episodes([3]), provenance={"source": "elicit-jax collect"}
    )
    write_demos(tmp_path / "mixed.parquet", concat_demos([both, collected]))
    with pytest.raises(ElicitError, match=r"not imported from a dataset.*drop --mask-key"):
        export(tmp_path / "mixed.parquet", "robomimic", tmp_path / "x.hdf5", mask_key="kept")
    export(tmp_path / "mixed.parquet", "robomimic", tmp_path / "x.hdf5")
    assert len(masks_of(tmp_path / "x.hdf5")["op_a"]) == 3


def test_robomimic_demos_become_a_lerobot_dataset(mh, tmp_path):
    _, demos = mh
    with pytest.raises(ElicitError, match="cannot tell the demonstrations' frame rate"):
        export(demos, "lerobot", tmp_path / "lr")
    summary = export(demos, "lerobot", tmp_path / "lr", fps=20)
    assert summary["mode"] == "new dataset" and summary["version"] == "v3.0"
    info = json.loads((tmp_path / "lr/meta/info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["fps"] == 20
    assert info["features"]["observation.state"]["names"][:4] == [
        "robot0_eef_pos.0",
        "robot0_eef_pos.1",
        "robot0_eef_pos.2",
        "robot0_eef_quat.0",
    ]
    same_core(import_lerobot(tmp_path / "lr"), read_demos(demos))


def test_episode_list_holds_integers_lerobot_filters_on(tmp_path):
    import pyarrow.dataset as pa_ds

    rng = np.random.default_rng(0)
    root = write_lerobot_v30(tmp_path / "ds", [lerobot_episode(rng, i, 5) for i in range(5)], ["t"])
    write_demos(tmp_path / "d.parquet", import_lerobot(root))
    export(tmp_path / "d.parquet", "lerobot", tmp_path / "sel.json", episodes=(1, 3, 4))
    ids = json.loads((tmp_path / "sel.json").read_text())["source_episodes"]
    assert ids == [1, 3, 4] and all(type(i) is int for i in ids)  # not "1", "3", "4"
    # LeRobotDataset(episodes=ids) selects frames with this Arrow predicate
    data = pa_ds.dataset(sorted(str(p) for p in (root / "data").glob("*/*.parquet")))
    got = data.to_table(filter=pa_ds.field("episode_index").isin(ids))
    assert sorted(set(got.column("episode_index").to_pylist())) == [1, 3, 4]
    # an episode with dropped pairs is not a source episode: no list for it
    _drop_pairs(tmp_path / "d.parquet", tmp_path / "kept.parquet", "renumber", episode=4)
    with pytest.raises(ElicitError, match="holds 2 of source episode 4's 5 steps"):
        export(tmp_path / "kept.parquet", "lerobot", tmp_path / "k.json")
    with pytest.raises(ElicitError, match="pass --fresh"):
        export(tmp_path / "kept.parquet", "lerobot", tmp_path / "k")
    assert export(tmp_path / "kept.parquet", "lerobot", tmp_path / "k", fresh=True)["fps"] == 10


@pytest.mark.parametrize(
    "writer, version", [(write_lerobot_v21, "v2.1"), (write_lerobot_v30, "v3.0")]
)
def test_lerobot_version_written_by_default(tmp_path, writer, version):
    rng = np.random.default_rng(0)
    root = writer(tmp_path / "ds", [lerobot_episode(rng, i, 4) for i in range(3)], ["t"])
    write_demos(tmp_path / "d.parquet", import_lerobot(root, operator="ann"))
    # a selection of the source and a new dataset are both the current v3.0 (LeRobot 0.4+
    # reads nothing else), and v2.1 when asked
    sub = export(tmp_path / "d.parquet", "lerobot", tmp_path / "sub")
    assert sub["version"] == "v3.0" and sub["mode"] == "selection of the source"
    assert any("the source is v2.1" in n for n in sub["notes"]) == (version == "v2.1")
    fresh = export(tmp_path / "d.parquet", "lerobot", tmp_path / "new", fresh=True)
    assert fresh["version"] == "v3.0"
    assert export(tmp_path / "d.parquet", "lerobot", tmp_path / "old", version="v2.1")
    imported = read_demos(tmp_path / "d.parquet")
    for out in ("sub", "new", "old"):
        info = json.loads((tmp_path / out / "meta/info.json").read_text())
        assert info["codebase_version"] == ("v2.1" if out == "old" else "v3.0")
        # both read back as imported (operators from the export's record)
        same_core(import_lerobot(tmp_path / out), imported)
    # and as a new robomimic file (joint-angle actions: data bounds)
    summary = export(tmp_path / "d.parquet", "robomimic", tmp_path / "r.hdf5")
    assert summary["reimport"].endswith("--action-bounds data -o demos.parquet")
    back = import_robomimic(
        tmp_path / "r.hdf5", obs_keys=["observation.state"], operators_from_masks="ann"
    )
    np.testing.assert_array_equal(back.obs, imported.obs)
    np.testing.assert_array_equal(back.action, imported.action)
    assert set(back.operator) == {"ann"} and back.success.tolist() == imported.success.tolist()


def test_collected_demos_round_trip_bit_equal(tmp_path, monkeypatch, capsys):
    import shlex

    from fixtures_data import run_cli

    from elicit_jax.sim.collect import CollectConfig, collect

    parts = []
    for op in ("base", "conflict-right"):
        collect(
            CollectConfig(task="reach-pillar", operator=op, episodes=2, batch=2),
            tmp_path / f"{op}.parquet",
        )
        parts.append(read_demos(tmp_path / f"{op}.parquet"))
    write_demos(tmp_path / "c.parquet", concat_demos(parts))
    collected = read_demos(tmp_path / "c.parquet")

    def cli(*args):
        code, out, err = run_cli(monkeypatch, capsys, *args)
        assert code == 0, err
        return out

    out = cli("export", tmp_path / "c.parquet", "-f", "robomimic", "-o", tmp_path / "c.hdf5")
    assert "note: no simulator states" in out and "rollout.enabled=False" in out
    with h5py.File(tmp_path / "c.hdf5", "r") as f:
        g = f["data/demo_0"]
        assert set(g) == {"actions", "rewards", "dones", "obs", "next_obs"}
        assert sorted(g["obs"]) == sorted(fld.name for fld in collected.obs_fields)
        assert g.attrs["num_samples"] == len(g["actions"]) and g["dones"][-1] == 1
        assert json.loads(f["data"].attrs["env_args"])["env_name"] == "reach-pillar"
        assert f["data"].attrs["total"] == collected.n_steps
        assert set(f["mask"]) == {"base", "conflict-right", "train", "valid"}
        assert g.attrs["init_seed"] == collected.extra["init_seed"][0]
    # the printed command reads it back
    line = next(x for x in out.splitlines() if x.startswith("read back: "))
    args = shlex.split(line.removeprefix("read back: elicit-jax "))
    cli(*[tmp_path / "r.parquet" if a == "demos.parquet" else a for a in args])
    same_core(read_demos(tmp_path / "r.parquet"), collected)
    out = cli("export", tmp_path / "c.parquet", "-f", "lerobot", "-o", tmp_path / "c_lr")
    assert "lerobot v3.0" in out and "frame rate 20 fps" in out
    cli("import", tmp_path / "c_lr", "-o", tmp_path / "l.parquet")
    same_core(read_demos(tmp_path / "l.parquet"), collected)
    stats = json.loads((tmp_path / "c_lr/meta/stats.json").read_text())
    assert {"q01", "q99"} <= set(stats["observation.state"]) and "init_seed" in stats
