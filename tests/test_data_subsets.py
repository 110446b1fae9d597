"""``demos list/select/concat``: subsets keep ids and source names, ranges work everywhere
episodes are selected, and the per-episode scores name the source demo."""

import numpy as np
import pytest
from fixtures_data import invoke

from elicit_jax.compat.selection import parse_selection
from elicit_jax.data.demos import from_episodes, read_demos, write_demos
from elicit_jax.errors import ElicitError


@pytest.fixture(scope="module")
def demos_file(tmp_path_factory):
    """8 demos named like a robomimic import (demo_10 .. demo_17), two operators."""
    d = tmp_path_factory.mktemp("subsets")
    rng = np.random.default_rng(0)
    eps = []
    for i in range(8):
        t = 5 + i
        eps.append(
            {
                "obs": rng.normal(size=(t, 3)),
                "action": rng.uniform(-1, 1, size=(t, 2)),
                "source_episode": np.full(t, f"demo_{10 + i}", dtype=object),
            }
        )
    demos = from_episodes(eps, operators=["alice"] * 5 + ["bob"] * 3)
    write_demos(d / "demos.parquet", demos)
    return d / "demos.parquet"


def test_select_ranges_and_split(demos_file, tmp_path):
    held, rest = tmp_path / "held.parquet", tmp_path / "rest.parquet"
    r = invoke("demos", "select", demos_file, "--episodes", "0-2,6", "-o", held)
    assert r.exit_code == 0, r.output
    assert "demo_16" in r.output  # the table names each episode's source demo
    h = read_demos(held)
    assert h.episode_ids.tolist() == [0, 1, 2, 6]  # ids of the input, not renumbered
    names = [h.extra["source_episode"][s] for _, s, _ in h.episode_bounds()]
    assert names == ["demo_10", "demo_11", "demo_12", "demo_16"]
    r = invoke("demos", "select", demos_file, "--exclude", "0-2,6", "-o", rest)
    assert r.exit_code == 0, r.output
    assert read_demos(rest).episode_ids.tolist() == [3, 4, 5, 7]
    r = invoke(
        "demos", "select", demos_file, "--operator", "bob", "--source-episodes",
        "demo_15,demo_17", "-o", tmp_path / "b.parquet",
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    assert read_demos(tmp_path / "b.parquet").episode_ids.tolist() == [5, 7]


def test_select_errors(demos_file, tmp_path):
    r = invoke("demos", "select", demos_file, "--episodes", "3-12", "-o", tmp_path / "x.parquet")
    assert isinstance(r.exception, ElicitError) and "has no episode 8" in str(r.exception)
    r = invoke("demos", "select", demos_file, "--episodes", "4-2", "-o", tmp_path / "x.parquet")
    assert "bad episode range" in str(r.exception)
    r = invoke("demos", "select", demos_file, "--operator", "carol", "-o", tmp_path / "x.parquet")
    assert "has no operator 'carol'" in str(r.exception)
    r = invoke("demos", "select", demos_file, "--episodes", "1", "-o", demos_file)
    assert "is the input" in str(r.exception)
    assert not (tmp_path / "x.parquet").exists()


def test_concat_renumbers_and_keeps_source_names(demos_file, tmp_path):
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    invoke("demos", "select", demos_file, "--episodes", "5-7", "-o", a)
    invoke("demos", "select", demos_file, "--episodes", "0,1", "-o", b)
    r = invoke("demos", "concat", a, b, "-o", tmp_path / "ab.parquet")
    assert r.exit_code == 0, r.output
    ab = read_demos(tmp_path / "ab.parquet")
    assert ab.episode_ids.tolist() == [0, 1, 2, 3, 4]
    starts = [s for _, s, _ in ab.episode_bounds()]
    assert [ab.extra["source_episode"][s] for s in starts] == [
        "demo_15", "demo_16", "demo_17", "demo_10", "demo_11",
    ]  # fmt: skip
    assert [int(ab.extra["part"][s]) for s in starts] == [0, 0, 0, 1, 1]
    r = invoke("demos", "list", tmp_path / "ab.parquet")
    assert r.exit_code == 0 and "demo_17" in r.output
    r = invoke("demos", "concat", a, "-o", tmp_path / "one.parquet")
    assert "at least two" in str(r.exception)


def test_episode_selections_accept_ranges_everywhere():
    sel = parse_selection("episodes:0-2,5")
    assert sel.values == ("0", "1", "2", "5")
    with pytest.raises(ElicitError, match="ranges like 0-4"):
        parse_selection("episodes:3-a")


def test_info_shows_ids_with_source_names(demos_file):
    r = invoke("info", demos_file)
    assert r.exit_code == 0
    assert "0 (demo_10)" in r.output and "7 (demo_17)" in r.output


def test_episode_scores_name_the_source_demo():
    from elicit_jax.compat.episode_summary import summarise_episodes

    pairs = {
        "episode": np.array([3, 3, 5]),
        "operator": np.array(["a", "a", "b"], dtype=object),
        "source_episode": np.array(["demo_3", "demo_3", "demo_9"], dtype=object),
        "incompatible": np.array([0, 1, 0]),
        "compatibility": np.ones(3),
        "likelihood": np.zeros(3),
        "novelty": np.zeros(3),
    }
    out = summarise_episodes(pairs, 0.05)
    assert out["source_episode"].tolist() == ["demo_3", "demo_9"]


def test_concat_keeps_each_episodes_task_into_a_lerobot_export(tmp_path):
    """Two imports of different tasks: each episode keeps its own (the LeRobot export lists
    it), not the first file's; `filter --base` concatenates with the same function."""
    import json

    import pyarrow.parquet as pq

    from elicit_jax.data.demos import concat_demos

    rng = np.random.default_rng(1)
    files = []
    for task, n in (("lift the cube", 2), ("open the drawer", 3)):
        eps = [
            {"obs": rng.normal(size=(4, 3)), "action": rng.uniform(-1, 1, size=(4, 2))}
            for _ in range(n)
        ]
        files.append(tmp_path / f"{n}.parquet")
        write_demos(files[-1], from_episodes(eps, operators="ann", task=task))
    r = invoke("demos", "concat", *files, "-o", tmp_path / "ab.parquet")
    assert r.exit_code == 0, r.output
    ab = read_demos(tmp_path / "ab.parquet")
    want = ["lift the cube"] * 2 + ["open the drawer"] * 3
    assert [ab.extra["task"][s] for _, s, _ in ab.episode_bounds()] == want
    assert ab.task == "lift the cube | open the drawer"
    r = invoke("export", tmp_path / "ab.parquet", "-f", "lerobot", "--fps", "10",
               "-o", tmp_path / "lr")  # fmt: skip
    assert r.exit_code == 0, r.output
    rows = pq.read_table(tmp_path / "lr/meta/episodes/chunk-000/file-000.parquet").to_pylist()
    assert [r["tasks"] for r in rows] == [[t] for t in want]
    assert json.loads((tmp_path / "lr/meta/info.json").read_text())["total_tasks"] == 2
    # one task everywhere: no task column, the task as it was
    same = concat_demos([read_demos(files[0]), read_demos(files[0])])
    assert "task" not in same.extra and same.task == "lift the cube"
