"""The report's table of the demos that conflict: per task, demo set, operator and collection,
counted from the ``conflicts`` column of a run's collected demos (hand-made here with known
values), carried by ``report-data.json`` through a rebuild, and absent from a report whose
demos (or whose ``report-data.json``) do not have it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from fixtures_data import toy_episode

from elicit_jax.artifact import dumps, read_json
from elicit_jax.data.demos import from_episodes, write_demos
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.evidence import DATA_FILE
from elicit_jax.pipeline.plan import build_graph
from elicit_jax.pipeline.run import rebuild_report, render_run_report, write_manifest
from elicit_jax.pipeline.spec import load_spec
from elicit_jax.pipeline.study_kinds import STAGE_KINDS

SPEC = """# a tiny filtering study on a task that measures traits: its contrast sets verify them
[pipeline]
name = "tiny-share"
profile = "cpu"
seeds = [0]
models = ["mlp"]
methods = ["base", "naive", "filtered"]

[[task]]
name = "robosuite-round"
operators = ["same-style", "conflict-down"]
base_episodes = 3
new_episodes = 4
holdout_episodes = 2
incompatible_operator = "conflict-down"
incompatible_episodes = 2

[collections]
seeds = [0, 1]
methods = ["base", "naive"]

[train]
hidden = [8, 8]
epochs = 2
checkpoint_every = 2

[evaluate]
rollouts = 2
"""

# Per collect stage id: whether each of its demos conflicts (the contrast sets are collection
# 0's only, as the fit runs there).
CONFLICTS = {
    "collect/robosuite-round/base": [False, False, False],
    "collect/robosuite-round/holdout": [False, False],
    "collect/robosuite-round/incompatible": [True, True],
    "collect/robosuite-round/new/same-style": [False, True, False, False],
    "collect/robosuite-round/new/conflict-down": [True, True, False, True],
    "collect/c1/robosuite-round/base": [False, True, False],
    "collect/c1/robosuite-round/new/same-style": [False, False, False, False],
    "collect/c1/robosuite-round/new/conflict-down": [True, True, True, True],
}
TITLE = "## Demos that conflict with the base operator's way"
# Worked by hand from CONFLICTS: e.g. conflict-down over both collections 3 + 4 = 7 of 8.
EXPECTED = """| task | demo set | operator | collection | demos | conflicting | share |
|---|---|---|---|---|---|---|
| robosuite-round | D_base | base | 0 | 3 | 0 | 0.0% |
| robosuite-round | D_base | base | 1 | 3 | 1 | 33.3% |
| robosuite-round | D_base | base | all | 6 | 1 | 16.7% |
| robosuite-round | contrast: held-out base (kept only if not conflicting) | base | 0 | 2 | 0 | 0.0% |
| robosuite-round | contrast: incompatible (kept only if conflicting) | conflict-down | 0 | 2 | 2 | 100.0% |
| robosuite-round | D_new | same-style | 0 | 4 | 1 | 25.0% |
| robosuite-round | D_new | same-style | 1 | 4 | 0 | 0.0% |
| robosuite-round | D_new | same-style | all | 8 | 1 | 12.5% |
| robosuite-round | D_new | conflict-down | 0 | 4 | 3 | 75.0% |
| robosuite-round | D_new | conflict-down | 1 | 4 | 4 | 100.0% |
| robosuite-round | D_new | conflict-down | all | 8 | 7 | 87.5% |"""  # noqa: E501


def _tiny_run(tmp_path: Path, with_column: bool = True, mixed: str = "") -> Path:
    """A run directory: the real plan and manifest, each collect stage's demos written by hand
    with the ``conflicts`` values of :data:`CONFLICTS` (``mixed``: that stage's first episode
    changes its value halfway); no other stage has finished."""
    (tmp_path / "tiny.toml").write_text(SPEC)
    spec = load_spec(tmp_path / "tiny.toml")
    graph = build_graph(spec, STAGE_KINDS.resolve)
    run = tmp_path / "run"
    run.mkdir()
    write_manifest(run, spec, graph)
    rng = np.random.default_rng(0)
    collects = [s for s in graph if s.kind == "collect"]
    assert {s.id for s in collects} == set(CONFLICTS)
    for stage in collects:
        episodes = []
        for i, flag in enumerate(CONFLICTS[stage.id]):
            ep = toy_episode(rng, 6)
            if with_column:
                ep["conflicts"] = np.full(6, flag)
                if stage.id == mixed and i == 0:
                    ep["conflicts"][3:] = not flag
            episodes.append(ep)
        cfg = stage.config["collect"]
        demos = from_episodes(episodes, operators=cfg["operator"], task=cfg["task"])
        (run / stage.output).parent.mkdir(parents=True, exist_ok=True)
        write_demos(run / stage.output, demos)
    return run


def _table(markdown: str) -> str:
    """The conflict table's lines of a report (from its header to the blank line after)."""
    return markdown[markdown.index(TITLE) :].split("\n\n")[1]


def test_the_report_counts_the_demos_that_conflict_by_hand_and_rebuilds_them(tmp_path):
    run = _tiny_run(tmp_path)
    md, page = render_run_report(run, tmp_path / "report")
    text = md.read_text()
    assert _table(text) == EXPECTED
    assert "<td>contrast: incompatible (kept only if conflicting)</td>" in page.read_text()
    assert "<td>87.5%</td>" in page.read_text()
    kept = read_json(md.parent / DATA_FILE)["data"]["conflicts"]
    assert len(kept) == len(CONFLICTS)
    assert {"task": "robosuite-round", "role": "new", "operator": "conflict-down", "n_demos": 4,
            "n_conflicts": 4, "require": "", "collection": 1} in kept  # fmt: skip
    # the report folder alone (the run deleted) rebuilds it byte for byte
    shutil.rmtree(run)
    rebuild_report(md.parent, tmp_path / "again")
    for name in ("report.md", "report.html", DATA_FILE):
        assert (tmp_path / "again" / name).read_bytes() == (md.parent / name).read_bytes(), name


def test_a_report_without_the_column_or_without_the_field_has_no_table(tmp_path):
    # demos without the column (a task measuring no traits): no table, no field kept
    plain = tmp_path / "plain"
    plain.mkdir()
    md, _ = render_run_report(_tiny_run(plain, with_column=False), plain / "report")
    assert "conflict with the base" not in md.read_text()
    assert "conflicts" not in read_json(md.parent / DATA_FILE)["data"]
    # a report-data.json kept before the field: it rebuilds as it was made, without the table
    measured = tmp_path / "measured"
    measured.mkdir()
    md, _ = render_run_report(_tiny_run(measured), measured / "report")
    text = md.read_text()
    header = json.loads((md.parent / DATA_FILE).read_text())
    del header["data"]["conflicts"]
    (md.parent / DATA_FILE).write_text(dumps(header) + "\n")
    rebuild_report(md.parent)
    start = text.index(TITLE)
    end = text.index("\n## ", start) + 1
    assert md.read_text() == text[:start] + text[end:]


def test_a_conflicts_column_that_changes_within_an_episode_is_a_one_line_error(tmp_path):
    run = _tiny_run(tmp_path, mixed="collect/c1/robosuite-round/base")
    where = r"c1/robosuite-round/base\.parquet: "
    with pytest.raises(ElicitError, match=where + "column 'conflicts' is not constant within"):
        render_run_report(run, tmp_path / "report")
    assert not (tmp_path / "report").exists()
