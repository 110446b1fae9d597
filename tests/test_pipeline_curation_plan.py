"""CUPID and the quality flags in the filtering study's graph (planning and configs; the
stages' libraries are tested in test_curation_cupid.py / test_curation_quality.py)."""

import pytest
from test_pipeline_spec import MINI

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.plan import build_graph
from elicit_jax.pipeline.spec import load_spec, parse_spec
from elicit_jax.pipeline.study_kinds import STAGE_KINDS

METHODS = ["base", "naive", "filtered", "cupid", "cupid-matched", "quality", "quality-matched"]


TASK = {**MINI["task"][0], "incompatible_operator": "conflict-over"}


def _spec(**over):
    task = {**TASK, "operators": ["mild", "conflict-right"]}
    raw = {**MINI, "pipeline": {**MINI["pipeline"], "methods": METHODS}, "task": [task]}
    return parse_spec({**raw, **over})


def test_tiny_pipeline_plans_cupid_and_quality():
    g = build_graph(
        _spec(cupid={"proj_dim": 64}, quality={"z_threshold": 3.0}), STAGE_KINDS.resolve
    )
    q = g["quality/reach-pillar/mild"]  # per task: the flags need no policy
    assert q.kind == "quality" and dict(q.inputs) == {"demos1": "collect/reach-pillar/new/mild"}
    assert q.config["quality"]["z_threshold"] == 3.0
    c = g["cupid/reach-pillar/mlp/conflict-right"]  # rolls out the naive policy of that operator
    assert c.inputs["policy"] == "train/reach-pillar/mlp/naive/conflict-right"
    assert c.inputs["demos0"] == "collect/reach-pillar/base"
    assert c.config["cupid"]["proj_dim"] == 64 and c.config["cupid"]["policy_seed"] == 0
    assert c.config["task"] == "reach-pillar"
    for method, source in (
        ("cupid", c.id),
        ("cupid-matched", c.id),
        ("quality", "quality/reach-pillar/conflict-right"),
        ("quality-matched", "quality/reach-pillar/conflict-right"),
    ):
        cut = g[f"filter/reach-pillar/mlp/{method}/conflict-right"]
        assert cut.kind == "curate" and cut.config["rate"] == (
            "m" if "matched" in method else "own"
        )
        if method.startswith("cupid"):
            assert cut.inputs["episode_scores"] == c.id
        else:
            assert cut.inputs["episode_scores"] == source
        trained = g[f"train/reach-pillar/mlp/{method}/conflict-right"]
        assert trained.inputs["demos1"] == cut.id
        assert (
            g[f"evaluate/reach-pillar/mlp/{method}-conflict-right"].inputs["policy"] == trained.id
        )
    assert {"cupid/reach-pillar/mlp/mild", "quality/reach-pillar/conflict-right"} <= set(
        g["report"].inputs
    )


def test_cupid_needs_naive_and_known_options():
    no_naive = {**MINI, "pipeline": {**MINI["pipeline"], "methods": ["base", "cupid"]}}
    with pytest.raises(ElicitError, match=r"cupid rolls out.*add 'naive'"):
        parse_spec(no_naive)
    with pytest.raises(ElicitError, match=r"\[cupid\] unknown option\(s\) proj"):
        build_graph(_spec(cupid={"proj": 64}), STAGE_KINDS.resolve)
    with pytest.raises(ElicitError, match=r"\[quality\] unknown option\(s\) z"):
        build_graph(_spec(quality={"z": 3}), STAGE_KINDS.resolve)


def test_shipped_filtering_study_includes_them():
    g = build_graph(load_spec("filtering", "cpu"), STAGE_KINDS.resolve)
    kinds = {s.kind for s in g.order}
    assert {"cupid", "quality"} <= kinds
    assert any(s.id.startswith("filter/square-nut/mlp/cupid-matched/") for s in g.order)
