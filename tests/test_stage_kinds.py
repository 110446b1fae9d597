"""The stage-kind registry: a kind registered in one place (one StageKind) is planned, run and
gathered without touching any other table; an unregistered kind, or a stage its kind does not
declare, is a one-line error; the shipped definitions plan against the registry."""

from __future__ import annotations

import io
import types
from pathlib import Path

import pytest
from rich.console import Console

from elicit_jax.artifact import make_header, read_json, write_json
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.gather import gather_fields
from elicit_jax.pipeline.graph import Graph, Stage
from elicit_jax.pipeline.run import write_manifest
from elicit_jax.pipeline.runner import StageContext, run_graph
from elicit_jax.pipeline.stage_kind import StageKind, StageKinds
from elicit_jax.pipeline.study_kinds import STAGE_KINDS, plan_definition


def _toy_resolve(raw: dict) -> dict:
    """Every key known, ``value`` a whole number (the library-config part of a real kind)."""
    if set(raw) - {"value"}:
        raise ElicitError(f"[toy] unknown keys {sorted(set(raw) - {'value'})}")
    return {"value": int(raw.get("value", 0))}


def _toy_stage(ctx: StageContext) -> None:
    """Writes its value plus the value of the toy it reads."""
    value = ctx.config["value"] + sum(read_json(p)["value"] for p in ctx.inputs.values())
    write_json(ctx.output, {**make_header("toy", 1, config=dict(ctx.config)), "value": value})


def _toy_rows(stage, path: Path) -> list[tuple[str, int]] | None:
    value = read_json(path)["value"]
    return None if value < 0 else [(stage["id"], value)]  # a negative toy is "not finished"


TOY = StageKind(
    "toy",
    _toy_stage,
    _toy_resolve,
    inputs=("previous",),
    outputs="toys/",
    reported=True,
    gather={"toys": _toy_rows},
)


def _plan(kinds: StageKinds, values: tuple[int, int]) -> Graph:
    first = Stage("toy/a", "toy", "toys/a.json", kinds.resolve("toy", {"value": values[0]}))
    second = Stage(
        "toy/b",
        "toy",
        "toys/b.json",
        kinds.resolve("toy", {"value": values[1]}),
        inputs={"previous": first.id},
    )
    graph = Graph([first, second])
    kinds.check(graph)
    return graph


def _run(kinds: StageKinds, graph: Graph, run_dir: Path) -> None:
    spec = types.SimpleNamespace(
        name="toys", kind="toy-study", profile="cpu", description="", source="-", text=""
    )
    run_dir.mkdir(exist_ok=True)
    write_manifest(run_dir, spec, graph)
    run_graph(graph, run_dir, kinds.functions(), console=Console(file=io.StringIO()))


def test_a_kind_registered_in_one_place_is_planned_run_and_gathered(tmp_path):
    kinds = STAGE_KINDS.extend(TOY)
    assert "toy" in kinds and "toy" not in STAGE_KINDS  # the shipped registry is untouched
    assert "toy" in kinds.reported()
    graph = _plan(kinds, (2, 3))
    assert dict(graph["toy/b"].config) == {"value": 3}
    _run(kinds, graph, tmp_path)
    run, rows = gather_fields(tmp_path, "report", kinds, ("toys", "lengths"))
    assert rows == {"toys": [("toy/a", 2), ("toy/b", 5)], "lengths": []}
    assert run["pipeline"] == "toys" and run["results"] == ()
    assert not any("not finished" in n for n in run["notes"])


def test_a_gatherer_that_finds_its_output_incomplete_marks_the_stage_unfinished(tmp_path):
    kinds = STAGE_KINDS.extend(TOY)
    _run(kinds, _plan(kinds, (1, -5)), tmp_path)
    run, rows = gather_fields(tmp_path, "report", kinds, ("toys",))
    assert rows == {"toys": [("toy/a", 1)]}
    assert any("1 stage(s) have not finished" in n and "toy/b" in n for n in run["notes"])


def test_the_config_resolver_is_the_kinds_own():
    kinds = STAGE_KINDS.extend(TOY)
    with pytest.raises(ElicitError, match=r"\[toy\] unknown keys \['speed'\]"):
        kinds.resolve("toy", {"speed": 3})
    assert kinds.resolve("toy", {"value": "4", "collection": 2}) == {"value": 4, "collection": 2}
    sized = kinds.resolve("toy", {"value": "4", "collection": 2, "sizes": "paper"})
    assert sized == {"value": 4, "collection": 2, "sizes": "paper"}  # named sizes kept too


def test_an_unregistered_kind_is_a_one_line_error():
    with pytest.raises(ElicitError) as planned:
        STAGE_KINDS.resolve("toy", {"value": 1})
    with pytest.raises(ElicitError) as checked:
        STAGE_KINDS.check(Graph([Stage("toy/a", "toy", "toys/a.json")]), "toys.toml")
    for error in (planned.value, checked.value):
        assert "\n" not in str(error) and "unknown stage kind 'toy'" in str(error)
        assert "registered: " in str(error) and "collect" in str(error)
    assert str(checked.value).startswith("toys.toml: ")


def test_a_stage_its_kind_does_not_declare_is_refused():
    kinds = STAGE_KINDS.extend(TOY)
    with pytest.raises(ElicitError, match="reads input 'other', which a 'toy' stage does not"):
        a = Stage("toy/a", "toy", "toys/a.json")
        kinds.check(Graph([a, Stage("toy/b", "toy", "toys/b.json", inputs={"other": a.id})]))
    with pytest.raises(ElicitError, match=r"writes 'maps/a\.json', outside the 'toys/'"):
        kinds.check(Graph([Stage("toy/a", "toy", "maps/a.json")]))


def test_a_kind_registers_once_and_extends_only_registered_kinds():
    kinds = STAGE_KINDS.extend(TOY)
    with pytest.raises(ElicitError, match="stage kind 'toy' is registered twice"):
        kinds.extend(TOY)
    with pytest.raises(ElicitError, match="cannot extend unregistered stage kind"):
        STAGE_KINDS.extend(gather={"toy": {"toys": _toy_rows}})
    with pytest.raises(ElicitError, match="already gathers lengths"):
        STAGE_KINDS.extend(gather={"collect": {"lengths": _toy_rows}})
    more = STAGE_KINDS.extend(gather={"collect": {"toys": _toy_rows}})
    assert set(more["collect"].gather) == {*STAGE_KINDS["collect"].gather, "toys"}


@pytest.mark.parametrize("name", ["quickstart", "filtering", "models", "elicitation"])
def test_shipped_definitions_plan_against_the_registry(name):
    _, graph, functions = plan_definition(name, "cpu")
    assert set(graph.kinds()) <= set(functions())
    report = graph["report"]
    reads = {graph[i].kind for i in report.inputs.values()}
    assert reads and reads <= set(STAGE_KINDS.reported())
