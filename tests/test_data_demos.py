"""The demonstration artifact: Parquet round trip, every validation error, atomic writes."""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from fixtures_data import toy_episode
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from elicit_jax.artifact import HEADER_KEY
from elicit_jax.data.demos import (
    DEMOS_SCHEMA_VERSION,
    SOURCE_EPISODE,
    DemosWarning,
    ObsField,
    concat_demos,
    fields_from_sizes,
    from_episodes,
    read_demos,
    write_demos,
)
from elicit_jax.errors import ElicitError


def make_demos(lengths=(3, 4, 2), operators=("alice", "bob", "alice"), seed=0, **meta):
    rng = np.random.default_rng(seed)
    eps = [toy_episode(rng, t) for t in lengths]
    for i, ep in enumerate(eps):
        ep[SOURCE_EPISODE] = np.full(len(ep["obs"]), f"demo_{10 + i}", object)
        ep["phase"] = np.arange(len(ep["obs"]), dtype=np.int64) * 2
        ep["goal"] = np.tile(np.array([[i, -i]], np.float32), (len(ep["obs"]), 1))
    defaults = dict(
        task="square",
        obs_fields=fields_from_sizes([("eef_pos", 3), ("object", 1)]),
        provenance={"source": "/data/x.hdf5", "sha256": "ab" * 32, "importer": "robomimic"},
    )
    return from_episodes(
        eps, operators=list(operators), successes=[True, False, True], **{**defaults, **meta}
    )


def _rewrite(path, out, table=None, header_update=None, drop=None):
    """Copy a demos file, editing its table or header (to build malformed files)."""
    table = pq.read_table(path) if table is None else table
    header = json.loads(table.schema.metadata[HEADER_KEY])
    header.update(header_update or {})
    if drop:
        table = table.drop_columns([drop])
    meta = dict(table.schema.metadata or {})
    meta[HEADER_KEY] = json.dumps(header).encode()
    pq.write_table(table.replace_schema_metadata(meta), out)
    return out


def test_round_trip_keeps_arrays_metadata_extras_and_provenance(tmp_path):
    demos = make_demos()
    path = tmp_path / "d.parquet"
    write_demos(path, demos, config={"a": 1}, seed=3)
    back = read_demos(path)
    for k in ("obs", "action", "reward", "episode", "step", "success"):
        np.testing.assert_array_equal(getattr(back, k), getattr(demos, k))
    assert back.operator.tolist() == demos.operator.tolist()
    assert back.task == "square"
    assert back.obs_fields == (ObsField("eef_pos", 0, 3), ObsField("object", 3, 4))
    assert back.provenance == demos.provenance
    assert (
        back.extra[SOURCE_EPISODE].tolist() == ["demo_10"] * 3 + ["demo_11"] * 4 + ["demo_12"] * 2
    )
    assert back.extra["phase"].dtype == np.int64
    np.testing.assert_array_equal(back.extra["phase"], demos.extra["phase"])
    assert back.extra["goal"].shape == (9, 2)
    np.testing.assert_array_equal(back.extra["goal"], demos.extra["goal"])
    # 3 + 4 + 2 = 9 steps in 3 episodes; episode 1 belongs to bob and failed.
    assert (back.n_steps, back.n_episodes, back.obs_dim, back.action_dim) == (9, 3, 4, 2)
    assert back.episode_operator() == {0: "alice", 1: "bob", 2: "alice"}
    assert back.success.tolist() == [True] * 3 + [False] * 4 + [True] * 2
    meta = json.loads(pq.read_schema(path).metadata[HEADER_KEY])
    assert meta["schema_version"] == DEMOS_SCHEMA_VERSION
    assert (meta["obs_dim"], meta["action_dim"], meta["n_episodes"]) == (4, 2, 3)
    assert meta["config"] == {"a": 1} and meta["seed"] == 3


def test_selection_and_concat_helpers():
    demos = make_demos()
    sub = demos.select_episodes([2, 0])
    assert sub.episode_ids.tolist() == [0, 2] and sub.n_steps == 5
    assert demos.select_operators(["bob"]).n_steps == 4
    both = concat_demos([demos, sub])
    # second part's episodes 0 and 2 become 3 and 4
    assert both.episode_ids.tolist() == [0, 1, 2, 3, 4]
    other = dataclasses.replace(sub, provenance={"source": "other"})
    assert "parts" in concat_demos([demos, other]).provenance


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: dataclasses.replace(d, obs=d.obs[:, None]), "must be 2-D"),
        (lambda d: dataclasses.replace(d, reward=d.reward[:-1]), "column 'reward' has 8 rows"),
        (
            lambda d: _set(d, "obs", (5, 1), np.nan),
            "non-finite obs[1] value at episode 1 (demo_11), step 2",
        ),
        (
            lambda d: _set(d, "action", (8, 0), np.inf),
            "non-finite action[0] value at episode 2 (demo_12), step 1",
        ),
        (
            lambda d: _set(d, "reward", 0, np.nan),
            "non-finite reward value at episode 0 (demo_10), step 0",
        ),
        (lambda d: _set(d, "episode", slice(7, 9), 0), "episode 0 is not contiguous"),
        (
            lambda d: _set(d, "step", 4, 3),
            "episode 1: steps must run 0..3 in order, found step 3 at position 1",
        ),
        (lambda d: _set(d, "step", slice(3, 7), np.arange(1, 5)), "episode 1: steps must run 0..3"),
        (
            lambda d: _set(d, "operator", 4, "carol"),
            "episode 1: operator changes within the episode at step 1",
        ),
        (lambda d: _set(d, "success", 4, True), "episode 1: success changes"),
        (
            lambda d: dataclasses.replace(d, obs_fields=(ObsField("x", 2, 9),)),
            "'x' 2:9 lies outside obs_dim 4",
        ),
        (
            lambda d: dataclasses.replace(d, action_low=(-1.0, -1.0, -1.0)),
            "do not match action_dim 2",
        ),
        (lambda d: dataclasses.replace(d, action_low=2.0), "invalid action bounds"),
    ],
)
def test_each_validation_error_names_file_and_place(tmp_path, edit, message):
    path = tmp_path / "bad.parquet"
    with pytest.raises(ElicitError) as err:
        write_demos(path, edit(make_demos()))
    text = str(err.value)
    assert text.startswith(f"{path}: ") and message in text and "\n" not in text
    assert not path.exists()


def _set(demos, field, index, value):
    arr = getattr(demos, field).copy()
    arr[index] = value
    return dataclasses.replace(demos, **{field: arr})


def test_empty_and_malformed_episode_lists_are_refused():
    with pytest.raises(ElicitError, match="no episodes"):
        from_episodes([])
    ep = toy_episode(np.random.default_rng(0), 3)
    with pytest.raises(ElicitError, match="episode 1 is empty"):
        from_episodes([ep, {"obs": np.zeros((0, 4)), "action": np.zeros((0, 2))}])
    with pytest.raises(ElicitError, match="episode 0: 'action' has 2 steps but 'obs' has 3"):
        from_episodes([{**ep, "action": ep["action"][:2]}])
    with pytest.raises(ElicitError, match="operators has 1 entries for 2 episodes"):
        from_episodes([ep, ep], operators=["a"])
    with pytest.raises(ElicitError, match="episode 1: 'obs' has width 5, episode 0 has 4"):
        from_episodes([ep, {**ep, "obs": np.zeros((3, 5))}])


def test_action_bounds_error_warn_clip(tmp_path):
    demos = make_demos()
    action = demos.action.copy()
    action[5, 1] = 1.5  # episode 1 (rows 3..6), step 2
    action[8, 0] = -3.0  # episode 2 (rows 7..8), step 1
    demos = dataclasses.replace(demos, action=action)
    path = tmp_path / "d.parquet"
    with pytest.raises(ElicitError) as err:
        write_demos(path, demos)
    assert str(err.value) == (
        f"{path}: action[1] = 1.5 outside bounds [-1, 1] at episode 1 (demo_11), step 2 "
        "(2 steps in all); pass --clip-actions or --warn-actions to accept"
    )
    with pytest.warns(DemosWarning, match=r"at episode 1 \(demo_11\), step 2"):
        write_demos(path, demos, bounds="warn")
    with pytest.warns(DemosWarning):  # the recorded policy makes later reads warn, not fail
        kept = read_demos(path)
    assert kept.action[5, 1] == pytest.approx(1.5)
    with pytest.raises(ElicitError, match="outside bounds"):
        read_demos(path, bounds="error")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        write_demos(path, demos, bounds="clip")
        clipped = read_demos(path)
    assert clipped.action[5, 1] == 1.0 and clipped.action[8, 0] == -1.0
    np.testing.assert_array_equal(
        np.delete(clipped.action, [5, 8], 0), np.delete(action, [5, 8], 0)
    )


def test_file_level_errors(tmp_path):
    good = tmp_path / "good.parquet"
    write_demos(good, make_demos())

    def err(path, **kw):
        with pytest.raises(ElicitError) as e:
            read_demos(path, **kw)
        text = str(e.value)
        assert text.startswith(f"{path}: ") and "\n" not in text
        return text

    assert "missing column(s) step" in err(_rewrite(good, tmp_path / "a.parquet", drop="step"))
    assert "missing column(s) phase" in err(_rewrite(good, tmp_path / "b.parquet", drop="phase"))
    newer = _rewrite(good, tmp_path / "c.parquet", header_update={"schema_version": 99})
    assert "schema version 99 is newer than this elicit-jax understands (1)" in err(newer)
    count = _rewrite(good, tmp_path / "d.parquet", header_update={"n_episodes": 4})
    assert "header lists 4 episodes but the file holds 3" in err(count)
    width = _rewrite(good, tmp_path / "e.parquet", header_update={"obs_dim": 5})
    assert "column 'obs' has width 4 but header says obs_dim=5" in err(width)
    kind = _rewrite(good, tmp_path / "f.parquet", header_update={"kind": "scores"})
    assert "is a 'scores' artifact, expected demonstrations" in err(kind)
    foreign = tmp_path / "g.parquet"
    pq.write_table(pa.table({"x": [1, 2]}), foreign)
    assert "has no elicit-jax header" in err(foreign)
    junk = tmp_path / "h.parquet"
    junk.write_text("not parquet at all")
    assert "not a readable Parquet file" in err(junk)
    assert "file not found" in err(tmp_path / "missing.parquet")
    # rows reordered on disk: episode 0's last row moved to the end
    table = pq.read_table(good)
    order = [0, 1, 3, 4, 5, 6, 7, 8, 2]
    split = _rewrite(good, tmp_path / "i.parquet", table=table.take(order))
    assert "episode 0 is not contiguous: its rows resume at row 8 (step 2)" in err(split)
    nulls = table.set_column(2, "step", pa.array([0, 1, None, 0, 1, 2, 3, 0, 1], pa.int32()))
    assert "column 'step' has 1 null rows" in err(_rewrite(good, tmp_path / "j.parquet", nulls))


def test_failing_write_leaves_nothing_behind(tmp_path, monkeypatch):
    demos = make_demos()
    path = tmp_path / "d.parquet"
    write_demos(path, demos)
    before = path.read_bytes()

    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(pq, "write_table", boom)
    # one line naming the output (pyarrow's own error names no file)
    with pytest.raises(ElicitError, match=r"d\.parquet: cannot write \(disk full\); nothing"):
        write_demos(path, make_demos(seed=1))
    assert path.read_bytes() == before  # the old artifact is untouched
    with pytest.raises(ElicitError, match=r"new\.parquet: cannot write"):
        write_demos(tmp_path / "new.parquet", demos)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.parquet"]  # no temp files


@settings(
    max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    lengths=st.lists(st.integers(1, 6), min_size=1, max_size=5),
    obs_dim=st.integers(1, 5),
    act_dim=st.integers(1, 3),
    names=st.lists(st.sampled_from(["a", "b", "émile", "op 3"]), min_size=5, max_size=5),
)
def test_round_trip_property(tmp_path, lengths, obs_dim, act_dim, names):
    rng = np.random.default_rng(len(lengths) * 7 + obs_dim)
    eps = [toy_episode(rng, t, obs_dim, act_dim) for t in lengths]
    demos = from_episodes(eps, operators=names[: len(eps)], successes=[t % 2 == 0 for t in lengths])
    path = tmp_path / "p.parquet"
    write_demos(path, demos)
    back = read_demos(path)
    np.testing.assert_array_equal(back.obs, demos.obs)
    np.testing.assert_array_equal(back.action, demos.action)
    assert back.operator.tolist() == demos.operator.tolist()
    assert [e - s for _, s, e in back.episode_bounds()] == list(lengths)
    assert back.success.tolist() == demos.success.tolist()
