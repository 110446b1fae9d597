"""Pipeline definitions and the study graph built from them (no training: configs only)."""

from __future__ import annotations

import pytest

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.plan import build_graph, collect_seed
from elicit_jax.pipeline.spec import builtin_names, load_spec, parse_spec, resolve_path

MINI = {
    "pipeline": {
        "name": "mini",
        "profile": "cpu",
        "seeds": [0, 1],
        "models": ["mlp"],
        "methods": ["base", "naive", "filtered", "random"],
    },
    "task": [
        {
            "name": "reach-pillar",
            "operators": ["a", "b"],
            "incompatible_operator": "b",
            "base_episodes": 5,
            "new_episodes": 4,
        }
    ],
    "train": {"epochs": 10},
    "filter": {"level": "pair"},
    "profiles": {"paper": {"train": {"epochs": 1000}}, "cpu": {"task": {"new_episodes": 3}}},
}


def _filtering_names() -> list[str]:
    """Shipped filtering definitions (elicitation studies: tests/test_study_pipeline.py)."""
    from elicit_jax.pipeline.elicitation.spec import read_kind
    from elicit_jax.pipeline.spec import resolve_path

    return [n for n in builtin_names() if read_kind(resolve_path(n)) == "filtering"]


def test_shipped_definitions_parse_under_both_profiles():
    assert {"quickstart", "filtering", "models"} <= set(_filtering_names())
    assert "elicitation" in builtin_names()
    for name in _filtering_names():
        for profile in ("cpu", "paper"):
            spec = load_spec(name, profile)
            assert spec.profile == profile
            assert spec.text.startswith("#")
            graph = build_graph(spec)
            assert graph.order[-1].id == "report"


def test_shipped_definitions_name_real_operators_and_valid_options():
    from elicit_jax.pipeline.study_kinds import STAGE_KINDS

    for name in _filtering_names():
        graph = build_graph(load_spec(name, "cpu"), STAGE_KINDS.resolve)
        assert graph["report"].config["pipeline"] == name


def test_unknown_operator_or_option_fails_before_running():
    from elicit_jax.pipeline.study_kinds import STAGE_KINDS

    bad_op = {
        **MINI,
        "task": [
            {**MINI["task"][0], "operators": ["nobody"], "incompatible_operator": "conflict-over"}
        ],
    }
    with pytest.raises(ElicitError, match="has no operator 'nobody'"):
        build_graph(parse_spec(bad_op), STAGE_KINDS.resolve)
    bad_opt = {
        **MINI,
        "task": [
            {**MINI["task"][0], "operators": ["mild"], "incompatible_operator": "conflict-over"}
        ],
        "train": {"epochz": 3},
    }
    with pytest.raises(ElicitError, match=r"\[train\] unknown option\(s\) epochz"):
        build_graph(parse_spec(bad_opt), STAGE_KINDS.resolve)


def test_profile_overrides_are_merged_over_sections():
    cpu = parse_spec(MINI)
    paper = parse_spec(MINI, profile="paper")
    assert cpu.section("train") == {"epochs": 10}
    assert paper.section("train") == {"epochs": 1000}
    assert cpu.tasks[0].new_episodes == 3 and paper.tasks[0].new_episodes == 4


def test_per_task_profile_overrides_and_task_filter():
    two = {
        **MINI,
        "task": [
            {**MINI["task"][0], "profiles": {"cpu": {"operators": ["a"], "new_episodes": 2}}},
            {**MINI["task"][0], "name": "square-nut"},
        ],
    }
    cpu, paper = parse_spec(two), parse_spec(two, profile="paper")
    # the task's own cpu table wins over [profiles.cpu.task] (new_episodes 3), which wins
    # over the [[task]] table (4); the other task gets only the profile-wide override
    assert (cpu.tasks[0].operators, cpu.tasks[0].new_episodes) == (("a",), 2)
    assert (cpu.tasks[1].operators, cpu.tasks[1].new_episodes) == (("a", "b"), 3)
    assert (paper.tasks[0].operators, paper.tasks[0].new_episodes) == (("a", "b"), 4)
    bad = {**MINI, "task": [{**MINI["task"][0], "profiles": {"gpu": {}}}]}
    with pytest.raises(ElicitError, match=r"\[task.profiles.gpu\]: unknown profile"):
        parse_spec(bad)
    only = load_spec("filtering", "cpu", tasks=("square-nut",))
    assert [t.name for t in only.tasks] == ["square-nut"]
    assert only.tasks[0].operators == ("same-style", "mild", "conflict-flip-pause")
    assert len(load_spec("filtering", "paper").tasks) == 3
    # robosuite's cpu study keeps the conflicting D_new only; the paper profile all three
    rs_cpu, rs_paper = load_spec("robosuite", "cpu"), load_spec("robosuite", "paper")
    assert {t.operators for t in rs_cpu.tasks} == {("conflict-down",)}
    assert {t.operators for t in rs_paper.tasks} == {("same-style", "mild", "conflict-down")}
    # collections are fixed in the definition before any run (3 under the cpu profile)
    assert rs_cpu.collections is not None and len(rs_cpu.collections.seeds) == 3
    with pytest.raises(ElicitError, match="no task nowhere in this definition"):
        load_spec("filtering", "cpu", tasks=("nowhere",))


@pytest.mark.parametrize(
    ("patch", "message"),
    [
        ({"pipeline": {"name": "x", "sedes": [0]}}, "unknown key"),
        ({"pipeline": {"name": "x", "profile": "gpu"}}, "unknown profile 'gpu'"),
        ({"pipeline": {"name": "x", "methods": ["naive"]}}, "must include 'base'"),
        ({"pipeline": {"name": "x", "methods": ["base", "magic"]}}, "unknown method 'magic'"),
        ({"task": []}, "at least one"),
        ({"task": [{"name": "t", "operators": ["a"]}]}, "missing 'incompatible_operator'"),
        (
            {
                "task": [
                    {
                        "name": "t",
                        "operators": ["a"],
                        "incompatible_operator": "a",
                        "base_episodes": 0,
                    }
                ]
            },
            "base_episodes must be at least 1",
        ),
        ({"bogus": {}}, "top level: unknown key"),
    ],
)
def test_bad_definitions_fail_with_one_line(patch, message):
    with pytest.raises(ElicitError, match=message) as info:
        parse_spec({**MINI, **patch}, source="x.toml")
    assert "\n" not in str(info.value) and str(info.value).startswith("x.toml: ")


def test_missing_file_names_the_shipped_ones(tmp_path):
    with pytest.raises(ElicitError, match=r"shipped definitions: .*quickstart"):
        resolve_path(tmp_path / "nope.toml")
    assert resolve_path("quickstart").name == "quickstart.toml"


def test_readme_style_path_finds_the_shipped_definition_outside_a_checkout(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no pipelines/ folder here
    assert resolve_path("pipelines/filtering.toml") == resolve_path("filtering")
    with pytest.raises(ElicitError, match="no such pipeline file"):
        resolve_path("elsewhere/filtering.toml")


def test_graph_shape_and_disjoint_contrast_sets():
    spec = parse_spec(MINI)
    graph = build_graph(spec)
    kinds = [s.kind for s in graph]
    # collects: base, holdout, incompatible, a, b = 5; trains: base + 2 naive + 2×2 filtered/random
    # = 7; evaluates 7; scores: contrast + 2 = 3; fit 1; filters 2 × 2 = 4; map 1; report 1.
    assert {k: kinds.count(k) for k in set(kinds)} == {
        "collect": 5,
        "train": 7,
        "evaluate": 7,
        "score": 3,
        "fit-thresholds": 1,
        "filter": 4,
        "map": 1,
        "report": 1,
    }
    seeds = {s.id: s.config["seed"] for s in graph if s.kind == "collect"}
    assert len(set(seeds.values())) == 5  # every demo set has its own collection seed
    task = spec.tasks[0]
    assert collect_seed(spec, task, "incompatible") != collect_seed(spec, task, "b")
    contrast = graph["score/reach-pillar/mlp/contrast"]
    assert set(contrast.inputs.values()) == {
        "train/reach-pillar/mlp/base",
        "collect/reach-pillar/holdout",
        "collect/reach-pillar/incompatible",
    }
    new_sets = {f"collect/reach-pillar/new/{o}" for o in ("a", "b")}
    assert not new_sets & set(contrast.inputs.values())
    assert graph["train/reach-pillar/mlp/base"].config["seeds"] == [0, 1]


def test_changed_filter_config_affects_only_filter_stages_and_their_dependents():
    spec_a = parse_spec(MINI)
    spec_b = parse_spec({**MINI, "filter": {"level": "episode"}})
    ga, gb = build_graph(spec_a), build_graph(spec_b)
    changed = {s.id for s in ga if dict(s.config) != dict(gb[s.id].config)}
    assert changed == {
        f"filter/reach-pillar/mlp/{m}/{o}" for m in ("filtered", "random") for o in ("a", "b")
    }
    affected = set().union(*(ga.dependents(i) for i in changed)) | changed
    untouched = {s.id for s in ga} - affected
    assert "train/reach-pillar/mlp/base" in untouched
    assert "train/reach-pillar/mlp/naive/a" in untouched
    assert "score/reach-pillar/mlp/a" in untouched
    assert {
        "train/reach-pillar/mlp/filtered/a",
        "evaluate/reach-pillar/mlp/random-b",
        "report",
    } <= affected


def test_profile_pipeline_overrides_and_the_shipped_filtering_seeds():
    spec = {**MINI, "profiles": {"cpu": {"pipeline": {"seeds": [0, 1, 2, 3, 4]}}}}
    assert parse_spec(spec).seeds == (0, 1, 2, 3, 4)
    assert parse_spec(spec, profile="paper").seeds == (0, 1)
    bad = {**MINI, "profiles": {"cpu": {"pipeline": {"name": "other"}}}}
    with pytest.raises(ElicitError, match=r"\[profiles.cpu.pipeline\]: unknown key\(s\) name"):
        parse_spec(bad)
    assert load_spec("filtering", "cpu").seeds == (0, 1, 2, 3, 4)
    assert load_spec("filtering", "paper").seeds == (0, 1, 2)


def test_curation_stages_and_their_inputs():
    spec = parse_spec(
        {
            **MINI,
            "pipeline": {
                **MINI["pipeline"],
                "methods": ["base", "naive", "filtered", "deminf", "demo-score-matched"],
            },
        }
    )
    g = build_graph(spec)
    deminf = g["deminf/reach-pillar/a"]  # one per task: DemInf needs no policy
    assert dict(deminf.inputs) == {
        "demos0": "collect/reach-pillar/base",
        "demos1": "collect/reach-pillar/new/a",
    }
    ds = g["demo-score/reach-pillar/mlp/b"]  # rolls out the naive policy of that operator
    assert ds.inputs["policy"] == "train/reach-pillar/mlp/naive/b"
    assert ds.config["policy_seed"] == 0
    cut = g["filter/reach-pillar/mlp/demo-score-matched/b"]
    assert cut.kind == "curate" and cut.inputs["episode_scores"] == ds.id
    assert cut.inputs["thresholds"] == "fit-thresholds/reach-pillar/mlp"
    assert (
        g["train/reach-pillar/mlp/deminf/a"].inputs["demos1"] == "filter/reach-pillar/mlp/deminf/a"
    )
    no_naive = {**MINI, "pipeline": {**MINI["pipeline"], "methods": ["base", "demo-score"]}}
    with pytest.raises(ElicitError, match="add 'naive' to methods"):
        parse_spec(no_naive)


def test_resolved_curate_config_takes_rate_level_and_deminf_cut():
    from elicit_jax.pipeline.study_kinds import STAGE_KINDS

    spec = parse_spec(
        {
            **MINI,
            "pipeline": {**MINI["pipeline"], "methods": ["base", "naive", "deminf-matched"]},
            "filter": {"level": "episode"},
            "deminf": {"drop_fraction": 0.3, "ks": [4]},
            "task": [
                {**MINI["task"][0], "operators": ["mild"], "incompatible_operator": "conflict-over"}
            ],
        }
    )
    g = build_graph(spec, STAGE_KINDS.resolve)
    cfg = g["filter/reach-pillar/mlp/deminf-matched/mild"].config
    assert (cfg["rate"], cfg["level"], cfg["drop_fraction"]) == ("m", "episode", 0.3)
    assert g["deminf/reach-pillar/mild"].config["deminf"]["ks"] == [4]


def test_sensitivity_stages_use_held_out_seeds_and_evaluation_states():
    sens = {"points": 3, "seeds": [10, 11], "eval_seed": 4, "operators": ["b"]}
    g = build_graph(parse_spec({**MINI, "sensitivity": sens}))
    points = [s for s in g if s.kind == "lambda-point"]
    assert [s.config["point"] for s in points] == [0, 1, 2]
    assert all(s.inputs["thresholds"] == "fit-thresholds/reach-pillar/mlp" for s in points)
    ev = g["evaluate/reach-pillar/mlp/heldout-lambda2-filtered-b"]
    assert ev.config["seeds"] == [10, 11] and ev.config["seed"] == 4 and ev.config["point"] == 2
    filt = g["filter/reach-pillar/mlp/heldout/lambda2/filtered/b"]
    assert filt.inputs["thresholds"] == "lambda-point/reach-pillar/mlp/2"
    assert g["train/reach-pillar/mlp/heldout/naive/b"].config["seeds"] == [10, 11]
    assert "train/reach-pillar/mlp/heldout/naive/a" not in {s.id for s in g}
    assert g["evaluate/reach-pillar/mlp/base"].config.get("seed") is None  # the study's own


@pytest.mark.parametrize(
    ("sens", "message"),
    [
        ({"seeds": [1]}, "disjoint from"),
        ({"eval_seed": 0}, "must differ from"),
        ({"points": 1}, "at least 2"),
        ({"tasks": ["nowhere"]}, "not \\[\\[task\\]\\]s"),
        ({"bogus": 1}, "unknown key"),
    ],
)
def test_bad_sensitivity_tables(sens, message):
    with pytest.raises(ElicitError, match=message):
        parse_spec({**MINI, "sensitivity": sens})
