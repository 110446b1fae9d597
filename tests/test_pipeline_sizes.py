"""Named study sizes (``[task.sizes.<name>]``, ``[pipeline] sizes``, ``pipeline run --sizes``):
the demo counts each planned stage collects, the default sizes' stages unchanged, one-line
errors for bad sizes, and the report's side-by-side table (no training here)."""

from __future__ import annotations

import dataclasses
import json
import tomllib

import pytest
from typer.testing import CliRunner

from elicit_jax.cli import app
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.plan import build_graph
from elicit_jax.pipeline.report_rows import ReportData, ResultRow
from elicit_jax.pipeline.spec import load_spec, parse_spec
from elicit_jax.pipeline.tables_sizes import sizes_heading, sizes_note, sizes_tables

SPEC = """
[pipeline]
name = "mini"
seeds = [0, 1]
methods = ["base", "naive"]
{head}
[[task]]
name = "round-nut"
operators = ["a", "b"]
base_episodes = 50
new_episodes = 50
incompatible_operator = "c"
[task.sizes.paper]
base_episodes = 30
new_episodes = 10
[[task]]
name = "square-nut"
operators = ["a"]
base_episodes = 50
new_episodes = 50
incompatible_operator = "c"
[task.sizes.paper]
base_episodes = 50
new_episodes = 50
"""
SMALL = "[task.sizes.small]\nbase_episodes = 4\nnew_episodes = 2\n"
"""The tiny sizes the tests add to ``test_pipeline_e2e.TINY``'s task."""


def _spec(head: str = "", text: str | None = None):
    text = text if text is not None else SPEC.format(head=head)
    return parse_spec(tomllib.loads(text), source="mini.toml", text=text)


def _episodes(graph) -> dict[str, int]:
    """Each collect stage's demo count (its raw config, or the resolved ``collect`` one)."""
    return {
        s.id: s.config.get("collect", s.config)["episodes"] for s in graph if s.kind == "collect"
    }


def test_paper_sizes_collect_the_papers_counts_per_stage():
    graph = build_graph(_spec('sizes = "paper"'))
    counts = _episodes(graph)
    assert counts["collect/sizes-paper/round-nut/base"] == 30
    assert counts["collect/sizes-paper/round-nut/new/a"] == 10
    assert counts["collect/sizes-paper/round-nut/new/b"] == 10
    assert counts["collect/sizes-paper/square-nut/base"] == 50
    assert counts["collect/sizes-paper/square-nut/new/a"] == 50
    assert not any("/sizes-paper/" not in k for k in counts)  # nothing of the default sizes
    for stage in graph:  # every stage reads its own sizes' inputs, and records the sizes
        if stage.kind != "report":
            assert stage.config["sizes"] == "paper", stage.id
            assert all("/sizes-paper/" in v for v in stage.inputs.values()), stage.id
    trained = next(s for s in graph if s.id == "train/sizes-paper/round-nut/mlp/naive/a")
    assert trained.inputs == {
        "demos0": "collect/sizes-paper/round-nut/base",
        "demos1": "collect/sizes-paper/round-nut/new/a",
    }
    report = list(graph)[-1]
    assert report.config["sizes"] == {"paper": {"round-nut": [30, 10], "square-nut": [50, 50]}}


def test_the_registry_keeps_the_sizes_in_every_resolved_config():
    """The stage kinds' config resolution keeps ``sizes`` beside the library's full config."""
    from test_pipeline_e2e import TINY

    from elicit_jax.pipeline.study_kinds import STAGE_KINDS

    text = TINY.replace("[train]", SMALL + "\n[train]")
    spec = dataclasses.replace(_spec(text=text), sizes=("small",))
    graph = build_graph(spec, STAGE_KINDS.resolve)
    assert {s.config["sizes"] for s in graph if s.kind != "report"} == {"small"}
    assert next(s for s in graph if s.kind == "collect").config["collect"]["episodes"] == 4


def test_default_sizes_keep_the_stages_of_a_run_without_sizes():
    text = SPEC.format(head="").split("[task.sizes.paper]")[0]  # one task, no sizes table
    plain = parse_spec(tomllib.loads(text), source="mini.toml", text=text)
    with_sizes = dataclasses.replace(_spec(), tasks=_spec().tasks[:1])
    a, b = list(build_graph(plain)), list(build_graph(with_sizes))
    assert len(a) == len(b) > 5 and a[-1].inputs == b[-1].inputs and "sizes" not in b[-1].config
    assert [(s.id, s.output, s.config, s.inputs) for s in a[:-1]] == [
        (s.id, s.output, s.config, s.inputs) for s in b[:-1]
    ]  # the report differs only by the definition's text


def test_both_sizes_side_by_side_and_equal_counts_planned_once():
    spec = load_spec_text(SPEC.format(head=""), sizes="default,paper")
    counts = _episodes(build_graph(spec))
    assert counts["collect/round-nut/base"] == 50 and counts["collect/round-nut/new/a"] == 50
    assert counts["collect/sizes-paper/round-nut/base"] == 30
    assert "collect/square-nut/base" in counts
    assert not any(k.startswith("collect/sizes-paper/square-nut") for k in counts)  # = default


_TMP = {}


def load_spec_text(text: str, **kwargs):
    path = _TMP["dir"] / "mini.toml"
    path.write_text(text)
    return load_spec(path, **kwargs)


@pytest.fixture(autouse=True)
def _tmp(tmp_path):
    _TMP["dir"] = tmp_path


@pytest.mark.parametrize(
    ("head", "sizes", "message"),
    [
        ('sizes = "papr"', None, "unknown sizes 'papr' (this definition defines: default, paper)"),
        ("", "papr", "unknown sizes 'papr' (this definition defines: default, paper)"),
        ("", "paper,paper", "sizes are listed twice"),
        ("sizes = []", None, "sizes must name at least one sizes"),
    ],
)
def test_an_invalid_sizes_is_one_line_naming_the_file(head, sizes, message):
    with pytest.raises(ElicitError) as e:
        load_spec_text(SPEC.format(head=head), sizes=sizes)
    text = str(e.value)
    assert message in text and "mini.toml" in text and "\n" not in text


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ("[task.sizes.default]\nbase_episodes = 3\nnew_episodes = 3", "not 'default'"),
        ("[task.sizes.small]\nbase_episodes = 3", "must set exactly base_episodes and new_"),
        ("[task.sizes.small]\nbase_episodes = 0\nnew_episodes = 3", "integers ≥ 1"),
        ("[task.sizes.small]\nbase_episodes = 3\nnew_episodes = 3\nseed = 1", "exactly"),
    ],
)
def test_a_bad_sizes_table_is_one_line(table, message):
    text = SPEC.format(head="") + table
    with pytest.raises(ElicitError, match=message):
        _spec(text=text)


def test_sizes_missing_for_a_task_names_it_and_a_task_filter_allows_it():
    text = SPEC.format(head="").replace(
        "[task.sizes.paper]\nbase_episodes = 50\nnew_episodes = 50\n", ""
    )
    with pytest.raises(ElicitError, match="sizes 'paper' is not defined for task square-nut"):
        load_spec_text(text, sizes="paper")
    spec = load_spec_text(text, sizes="paper", tasks=("round-nut",))
    assert spec.sizes == ("paper",)


def test_pipeline_run_refuses_an_unknown_sizes_in_one_line(tmp_path):
    path = tmp_path / "mini.toml"
    path.write_text(SPEC.format(head=""))
    result = CliRunner().invoke(
        app, ["pipeline", "status", str(path), "--sizes", "nope", "-o", str(tmp_path / "r")]
    )
    assert result.exit_code != 0 and isinstance(result.exception, ElicitError)
    msg = str(result.exception)
    assert "unknown sizes 'nope'" in msg and str(path) in msg and "\n" not in msg
    assert not (tmp_path / "r").exists()


def _row(task, method, op, seed, success, sizes="default", collection=0):
    label = task if sizes == "default" else f"{task} ({sizes} sizes)"
    return ResultRow(label, "mlp", method, op, seed, success, 100.0, 50, "final", "x",
                     collection=collection, sizes=sizes)  # fmt: skip


def test_the_report_sets_the_sizes_side_by_side():
    sizes = {"default": {"round-nut": [50, 50], "square-nut": [50, 50]},
             "paper": {"round-nut": [30, 10], "square-nut": [50, 50]}}  # fmt: skip
    results = []
    for seed, (b, n, pb, pn) in enumerate([(0.3, 0.5, 0.2, 0.1), (0.3, 0.6, 0.3, 0.1)]):
        results += [_row("round-nut", "base", None, seed, b),
                    _row("round-nut", "naive", "a", seed, n),
                    _row("round-nut", "base", None, seed, pb, "paper"),
                    _row("round-nut", "naive", "a", seed, pn, "paper"),
                    _row("square-nut", "base", None, seed, b),
                    _row("square-nut", "naive", "a", seed, b + 0.1 + 0.05 * seed)]  # fmt: skip
    data = ReportData("mini", "cpu", "", "runs/x", "", tuple(results),
                      configs={"report": {"report": {"sizes": sizes}}})  # fmt: skip
    [(title, (header, rows))] = sizes_tables(data)
    assert header[3:] == ["sizes", "D_base + D_new", "Base", "Naive", "Naive − Base"]
    assert [r[:5] for r in rows] == [
        ["round-nut", "mlp", "a", "default", "50 + 50"],
        ["round-nut", "mlp", "a", "paper", "30 + 10"],
        ["square-nut", "mlp", "a", "default", "50 + 50"],
        ["square-nut", "mlp", "a", "paper (= default)", "50 + 50"],
    ]
    assert rows[0][5:7] == ["30.0 (0.0)", "55.0 (7.1)"] and rows[0][7].startswith("+25.0 [")
    assert rows[1][5:7] == ["25.0 (7.1)", "10.0 (0.0)"] and rows[1][7].startswith("-15.0 [")
    assert rows[3][7] == "as default (the same policies)" and rows[2][7].startswith("+12.5 [")
    assert "Holm-adjusted over the 3 differences" in title
    assert sizes_heading(data) == "; sizes default, paper"
    assert "**paper** (round-nut 30 + 10 per operator" in sizes_note(data)[0]
    plain = dataclasses.replace(data, configs={})
    assert sizes_tables(plain) == [] and sizes_heading(plain) == "" and sizes_note(plain) == []


def test_shipped_robosuite_definitions_have_the_papers_proportions():
    """Round Nut 30 + 10 per operator, Square Nut 50 + 50 (planned once beside the default)."""
    from elicit_jax.pipeline.study_kinds import plan_definition

    for name in ("robosuite", "phenomenon-robosuite"):
        spec, graph, _ = plan_definition(name, "cpu", sizes="default,paper")
        counts = _episodes(graph)
        assert counts["collect/sizes-paper/robosuite-round/base"] == 30
        assert counts["collect/sizes-paper/robosuite-round/new/conflict-down"] == 10
        assert counts["collect/robosuite-round/base"] == 50
        assert not any(k.startswith("collect/sizes-paper/robosuite-square") for k in counts)
        assert spec.sizes == ("default", "paper")
        alone, _, _ = plan_definition(name, "cpu")
        assert alone.sizes == ("default",)


def test_rollouts_carry_their_sizes_and_older_tables_read_as_default(tmp_path):
    """An evaluation of named sizes gives results labelled with them (column ``sizes`` of the
    study's rollout table); a rollout table kept before sizes reads as the default sizes."""
    from test_report_rebuild import HAND, _config, _rollouts, _write_eval

    from elicit_jax.pipeline.evidence import cell_frame, result_rows_of

    path = tmp_path / "e.parquet"
    _write_eval(path, _rollouts(HAND))
    frame = cell_frame({**_config("reported"), "sizes": "paper"}, path)
    (row,) = result_rows_of(frame)
    assert row.sizes == "paper" and row.task == "reach-pillar (paper sizes)"
    (plain,) = result_rows_of(cell_frame(_config("reported"), path))
    assert plain.sizes == "default" and plain.task == "reach-pillar"
    assert dataclasses.replace(row, task=plain.task, sizes="default") == plain
    old = frame.drop(columns=["sizes"])
    assert "sizes" not in old and read_back(old, tmp_path)["sizes"].eq("default").all()


def read_back(frame, folder):
    """``frame`` written as a report folder's rollout table and read back by ``read_raw``."""
    from elicit_jax.pipeline.evidence import (
        DATA_FILE,
        DATA_KIND,
        read_raw,
        write_rollouts_table,
    )

    write_rollouts_table(folder / "rollouts.parquet", frame, "mini", "cpu")
    (folder / DATA_FILE).write_text(json.dumps({"kind": DATA_KIND}))
    return read_raw(folder, (DATA_KIND,))[1]


def test_tiny_run_at_two_sizes_reports_them_side_by_side_and_rebuilds(tmp_path):
    """A real tiny run: ``--sizes small`` after nothing, then ``--sizes default,small`` runs
    only the default sizes' stages; the report sets both side by side and rebuilds byte for
    byte from its folder."""
    import os

    from rich.console import Console
    from test_pipeline_e2e import TINY

    from elicit_jax.pipeline.gather import gather
    from elicit_jax.pipeline.run import PipelineRunConfig, rebuild_report, run_pipeline
    from elicit_jax.pipeline.study_kinds import STAGE_KINDS

    text = TINY.replace('methods = ["base", "naive", "filtered"]', 'methods = ["base", "naive"]')
    text = text.replace("[train]", SMALL + "\n[train]")
    spec, out = tmp_path / "tiny.toml", tmp_path / "run"
    spec.write_text(text)

    def run(sizes: str):
        console = Console(file=open(os.devnull, "w"))  # noqa: SIM115
        cfg = PipelineRunConfig(pipeline=str(spec), out=str(out), progress=False, sizes=sizes)
        return run_pipeline(cfg, console=console)

    first = run("small")
    assert all("/sizes-small/" in s for s in first.result.ran if s != "report")
    both = run("default,small")
    assert not any("/sizes-small/" in s for s in both.result.ran)  # cached from the first run
    data = gather(out, STAGE_KINDS)
    assert {(r.task, r.method, r.sizes) for r in data.results} == {
        ("reach-pillar", "base", "default"), ("reach-pillar", "naive", "default"),
        ("reach-pillar (small sizes)", "base", "small"),
        ("reach-pillar (small sizes)", "naive", "small"),
    }  # fmt: skip
    report = both.report_md.read_text()
    assert "(cpu profile; sizes default, small)" in report.splitlines()[0]
    assert "## Sizes side by side" in report and "| 4 + 2 |" in report
    assert "**small** (reach-pillar 4 + 2 per operator)" in report
    md, _ = rebuild_report(out / "report", tmp_path / "rebuilt")
    assert md.read_text() == report
