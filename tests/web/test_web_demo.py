"""The `serve --demo` inputs run on the pipeline engine: the quickstart's stages, cut to what
the demo serves, in a cache directory keyed by a hash; a build cut short resumes and nothing
looks finished before `recipe.json` is written."""

from __future__ import annotations

import dataclasses
import io
import json

import pytest
from rich.console import Console

from elicit_jax.artifact import dumps
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline import serve_demo as demo

QUIET = Console(file=io.StringIO())


def test_demo_graph_is_the_quickstart_stages_up_to_the_thresholds():
    recipe = demo.DemoRecipe()
    graph = demo.demo_graph(recipe)
    assert [(s.id, s.kind) for s in graph.order] == [
        ("collect/reach-pillar/base", "collect"),
        ("collect/reach-pillar/holdout", "collect"),
        ("collect/reach-pillar/incompatible", "collect"),
        ("train/reach-pillar/mlp/base", "train"),
        ("score/reach-pillar/mlp/contrast", "score"),
        ("fit-thresholds/reach-pillar/mlp", "fit-thresholds"),
    ]
    # the sets the recipe names: operator, size, and seed (seed, seed + 1, seed + 2)
    collected = [
        (c["operator"], c["episodes"], c["seed"])
        for c in (graph[f"collect/reach-pillar/{r}"].config["collect"] for r in
                  ("base", "holdout", "incompatible"))
    ]  # fmt: skip
    assert collected == [("base", 20, 0), ("base", 4, 1), ("conflict-over", 4, 2)]
    # the train stage resolves exactly the training config the cache key covers
    trained = graph["train/reach-pillar/mlp/base"].config["train"]
    assert trained == json.loads(dumps(demo.train_config(recipe).to_dict()))
    assert (trained["hidden"], trained["ensemble_size"], trained["epochs"]) == ([128, 128], 5, 200)
    fit = graph["fit-thresholds/reach-pillar/mlp"]
    assert (fit.config["compatible_operator"], fit.config["incompatible_operator"]) == (
        "base",
        "conflict-over",
    )
    assert dict(graph["score/reach-pillar/mlp/contrast"].inputs) == {
        "policy": "train/reach-pillar/mlp/base",
        "demos0": "collect/reach-pillar/holdout",
        "demos1": "collect/reach-pillar/incompatible",
    }


def test_the_cache_key_covers_the_stage_graph(monkeypatch):
    recipe = demo.DemoRecipe()
    key = demo.recipe_hash(recipe)
    assert demo.recipe_hash(dataclasses.replace(recipe, contrast_episodes=5)) != key
    with monkeypatch.context() as m:  # a changed stage config builds anew
        real = demo.demo_graph
        m.setattr(demo, "demo_graph", lambda r: real(dataclasses.replace(r, seed=1)))
        assert demo.recipe_hash(recipe) != key
    assert demo.recipe_hash(recipe) == key


def _fake_registry(calls: list[str], fail: set[str]):
    """Stage functions that write a marker output (the cache logic under test, not the
    library's work), failing once on the stage ids in ``fail``."""

    def stage(ctx):
        calls.append(ctx.stage.id)
        if ctx.stage.id in fail:
            fail.discard(ctx.stage.id)
            raise ElicitError("cut short")
        if ctx.stage.kind == "collect" or ctx.stage.kind == "fit-thresholds":
            ctx.output.write_text(ctx.stage.id)
        else:
            ctx.output.mkdir()
            (ctx.output / "artifact.json").write_text("{}")

    return {k: stage for k in ("collect", "train", "score", "fit-thresholds")}


def test_a_build_cut_short_looks_unfinished_and_resumes(tmp_path, monkeypatch):
    from elicit_jax.pipeline import study_kinds

    recipe = demo.DemoRecipe()
    calls: list[str] = []
    fail = {"fit-thresholds/reach-pillar/mlp"}
    monkeypatch.setattr(study_kinds, "stage_functions", lambda: _fake_registry(calls, fail))
    with pytest.raises(ElicitError, match="cut short"):
        demo.demo_inputs(recipe, tmp_path, echo=lambda _: None, console=QUIET)
    out = tmp_path / demo.recipe_hash(recipe)[:16]
    assert not (out / demo.RECIPE_FILE).exists() and len(calls) == 6
    inputs = demo.demo_inputs(recipe, tmp_path, echo=lambda _: None, console=QUIET)
    assert calls[6:] == ["fit-thresholds/reach-pillar/mlp"]  # the finished stages are kept
    assert (out / demo.RECIPE_FILE).is_file()
    assert inputs.base_demos == out / "data/reach-pillar/base.parquet"
    assert inputs.policy == out / "policies/reach-pillar/mlp/base"
    assert inputs.thresholds == out / "thresholds/reach-pillar/mlp.json"
    assert inputs.thresholds.read_text() == "fit-thresholds/reach-pillar/mlp"
    assert demo.demo_inputs(recipe, tmp_path, echo=lambda _: None, console=QUIET) == inputs
    assert len(calls) == 7  # reused: nothing ran
