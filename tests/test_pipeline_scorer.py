"""The scoring policy of a filtering study (``[scorer]``): its training stage, the score stages
wired to it, its validation, the report's line about it, and without it the stage graph of
every shipped definition as before (so existing run folders stay cached)."""

from __future__ import annotations

import copy
import hashlib
import json
import os
import tomllib
from pathlib import Path

import pytest
from rich.console import Console

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.definition import read_kind
from elicit_jax.pipeline.gather import training_note
from elicit_jax.pipeline.plan import build_graph, unresolved
from elicit_jax.pipeline.spec import builtin_names, load_spec, parse_spec, resolve_path
from elicit_jax.pipeline.study_kinds import STAGE_KINDS, study_kind

TOY = {
    "pipeline": {
        "name": "toy",
        "profile": "cpu",
        "seeds": [3, 4],
        "models": ["mlp"],
        "methods": ["base", "naive", "filtered", "random"],
    },
    "task": [
        {
            "name": "reach-pillar",
            "operators": ["conflict-right", "same-style"],
            "incompatible_operator": "conflict-over",
            "base_episodes": 5,
            "new_episodes": 4,
        }
    ],
    "train": {"epochs": 10},
    "profiles": {"cpu": {"train": {"epochs": 7, "hidden": [16, 16]}}},
}


def _with(**tables) -> dict:
    data = copy.deepcopy(TOY)
    data.update(tables)
    return data


def test_scorer_trains_on_d_base_and_every_score_stage_reads_it():
    data = _with(scorer={"profile": "paper", "epochs": 12})
    graph = build_graph(parse_spec(data), STAGE_KINDS.resolve)
    scorer = graph["train/reach-pillar/mlp/scorer"]
    assert scorer.output == "policies/reach-pillar/mlp/scorer"
    assert dict(scorer.inputs) == {"demos0": "collect/reach-pillar/base"}
    train = scorer.config["train"]
    # the first training seed; the paper profile's sizes with the scorer's own epochs: neither
    # [train] (epochs 10) nor the cpu profile's [profiles.cpu.train] (7, 16 × 16) apply to it
    assert (train["seeds"], train["epochs"]) == ([3], 12)
    assert (train["ensemble_size"], train["hidden"]) == (5, [1024, 1024])
    assert scorer.config["profile"] == "paper" and scorer.config["method"] == "scorer"
    scores = [s for s in graph if s.kind == "score"]
    assert len(scores) == 3  # the contrast sets and both D_new
    assert all(s.inputs["policy"] == scorer.id for s in scores)
    assert all(s.config["policy_seed"] == 3 for s in scores)
    base = graph["train/reach-pillar/mlp/base"]
    assert base.config["train"]["epochs"] == 7 and base.config["train"]["seeds"] == [3, 4]
    # the compared policies are as without [scorer]; only the scorer and the score inputs differ
    plain = build_graph(parse_spec(TOY), STAGE_KINDS.resolve)
    assert {s.id for s in graph} - {s.id for s in plain} == {scorer.id}
    assert len(graph) == len(plain) + 1
    for stage in plain:
        other = graph[stage.id]
        if stage.kind == "report":
            continue
        inputs = {k: (base.id if v == scorer.id else v) for k, v in other.inputs.items()}
        assert (other.config, inputs) == (stage.config, dict(stage.inputs)), stage.id


def test_the_profile_scorer_table_and_collections_and_sizes():
    data = _with(
        scorer={"profile": "paper", "epochs": 12},
        collections={"seeds": [0, 1], "methods": ["base", "filtered"]},
    )
    data["profiles"]["cpu"]["scorer"] = {"hidden": [64, 64]}
    data["task"][0]["sizes"] = {"small": {"base_episodes": 3, "new_episodes": 2}}
    spec = load_spec_data(data, sizes="default,small")
    graph = build_graph(spec, STAGE_KINDS.resolve)
    scorers = sorted(s.id for s in graph if s.id.endswith("/scorer"))
    assert scorers == [
        "train/c1/reach-pillar/mlp/scorer",
        "train/reach-pillar/mlp/scorer",
        "train/sizes-small/c1/reach-pillar/mlp/scorer",
        "train/sizes-small/reach-pillar/mlp/scorer",
    ]
    for sid in scorers:
        train = graph[sid].config["train"]
        assert (train["hidden"], train["epochs"]) == ([64, 64], 12)  # [profiles.cpu.scorer]
        demos = graph[graph[sid].inputs["demos0"]]  # D_base of its own collection and sizes
        assert demos.kind == "collect" and demos.id.endswith("reach-pillar/base")
        assert demos.id.split("/")[1:-2] == sid.split("/")[1:-3]  # same collection and sizes
    for s in graph:
        if s.kind == "score":
            assert s.inputs["policy"].endswith("/scorer")
            assert s.inputs["policy"].split("/")[1:-3] == s.id.split("/")[1:-3]
    # under the paper profile [profiles.cpu.scorer] does not apply
    paper = build_graph(parse_spec(data, profile="paper"), STAGE_KINDS.resolve)
    assert paper["train/reach-pillar/mlp/scorer"].config["train"]["hidden"] == [1024, 1024]


def load_spec_data(data: dict, sizes: str) -> object:
    """A definition given as tables, with ``--sizes`` applied as ``load_spec`` does."""
    import dataclasses

    from elicit_jax.pipeline.sizes import choose_sizes

    spec = parse_spec(data, source="toy.toml")
    return dataclasses.replace(spec, sizes=choose_sizes(sizes, spec.tasks, "toy.toml"))


def test_a_scorer_that_trains_as_the_base_policy_is_the_base_policy():
    same = _with(scorer={"profile": "cpu", "epochs": 7, "hidden": [16, 16]})
    graph = build_graph(parse_spec(same), STAGE_KINDS.resolve)
    assert not [s for s in graph if s.id.endswith("/scorer")]
    assert {s.inputs["policy"] for s in graph if s.kind == "score"} == {
        "train/reach-pillar/mlp/base"
    }
    other = _with(scorer={"profile": "cpu", "epochs": 8, "hidden": [16, 16]})
    ids = [s.id for s in build_graph(parse_spec(other), STAGE_KINDS.resolve)]
    assert "train/reach-pillar/mlp/scorer" in ids


@pytest.mark.parametrize(
    ("scorer", "message"),
    [
        # the allowed keys listed: [train]'s and profile
        ({"profile": "paper", "epochz": 3}, r"\[scorer\] unknown option\(s\) epochz .*, profile,"),
        ({"profile": "gpu"}, r"\[scorer\] unknown profile 'gpu'; choose one of paper, cpu"),
        ({"profile": 3}, r"\[scorer\] profile must be a profile name"),
        ({"seeds": [0]}, r"\[scorer\] seeds: the scorer trains one seed"),
        ({"epochs": 0}, r"\[scorer\] invalid training config"),
    ],
)
def test_a_bad_scorer_table_is_one_line_naming_the_file(tmp_path, scorer, message):
    path = tmp_path / "mine.toml"
    table = "".join(f"{k} = {json.dumps(v)}\n" for k, v in scorer.items())
    head, _, rest = TINY.partition("[scorer]\n")
    path.write_text(head + rest.partition("\n\n")[2] + "\n[scorer]\n" + table)
    with pytest.raises(ElicitError, match=message) as info:
        load_spec(path)
    assert "\n" not in str(info.value) and str(info.value).startswith(f"{path}: ")


def test_scorer_is_refused_where_nothing_is_scored_and_in_an_elicitation_study(tmp_path):
    bare = _with(scorer={"profile": "paper"})
    bare["pipeline"]["methods"] = ["base", "naive"]
    with pytest.raises(ElicitError, match=r"x.toml: \[scorer\]: no method of this study scores"):
        parse_spec(bare, source="x.toml")
    text = resolve_path("elicitation").read_text()
    for table in ('[scorer]\nprofile = "paper"\n', "[profiles.cpu.scorer]\nepochs = 5\n"):
        path = tmp_path / "study.toml"
        path.write_text(text + "\n" + table)
        kind = study_kind(read_kind(path), path)
        with pytest.raises(ElicitError, match="applies to filtering studies only") as info:
            load_spec(path, parse=kind.parse)
        assert str(info.value).startswith(f"{path}: ") and "\n" not in str(info.value)


MAIN_GRAPHS = {
    # digests of every shipped definition's stage graph (ids, kinds, outputs, raw configs,
    # inputs, seeds; the report stage aside, as it records the definition's text), planned by
    # the code at 1d974d4, before [scorer] existed; robosuite's with its [scorer] table removed
    "elicitation/cpu": "463f420979fa59cf",
    "elicitation/paper": "8221adce2b23fddf",
    "filtering/cpu": "f1667d5d901b3ad6",
    "filtering/paper": "aa33a3762653f669",
    "models/cpu": "65436cadc8578865",
    "models/paper": "2c19dc07579f5f05",
    "phenomenon/cpu": "34f1894ced732564",
    "phenomenon/paper": "fd774088ef40eaea",
    "phenomenon-robosuite/cpu": "c8991c05f1c0d47e",
    "phenomenon-robosuite/paper": "55d36e9f50b67378",
    "quickstart/cpu": "9b6ab3fac6a0df1b",
    "quickstart/paper": "44d4e2536ab64886",
    "robosuite/cpu": "8dba8661f82e5603",
    "robosuite/paper": "ef539b60b717fee2",
}


def _digest(graph) -> str:
    rows = [
        [s.id, s.kind, s.output, dict(s.config), dict(s.inputs), s.seed]
        for s in graph
        if s.kind not in ("report", "study-report")
    ]
    return hashlib.sha256(json.dumps(rows, sort_keys=True).encode()).hexdigest()[:16]


def test_without_scorer_every_shipped_definition_plans_the_stages_it_did_before():
    found = {}
    for name in builtin_names():
        path = resolve_path(name)
        kind = study_kind(read_kind(path), path)
        data = tomllib.loads(path.read_text())
        data.pop("scorer", None)
        for prof in ("cpu", "paper"):
            spec = kind.parse(data, source=str(path), profile=prof)
            found[f"{name}/{prof}"] = _digest(kind.build_graph(spec, unresolved))
    assert found == MAIN_GRAPHS
    # robosuite's scorer: a cpu study trains one per collection; under the paper profile it
    # trains as the base policy does, so the base policy scores and the graph is as before
    for prof in ("cpu", "paper"):
        graph = build_graph(load_spec("robosuite", prof), unresolved)
        scorers = [s for s in graph if s.id.endswith("/scorer")]
        assert len(scorers) == (6 if prof == "cpu" else 0)
    paper = build_graph(load_spec("robosuite", "paper"), unresolved)
    assert _digest(paper) == MAIN_GRAPHS["robosuite/paper"]


def test_the_shipped_robosuite_scorer_is_the_papers_size_under_the_cpu_profile():
    graph = build_graph(load_spec("robosuite", "cpu"), STAGE_KINDS.resolve)
    train = graph["train/robosuite-round/mlp/scorer"].config["train"]
    assert (train["ensemble_size"], train["hidden"], train["epochs"]) == (5, [1024, 1024], 1000)
    assert (train["seeds"], train["checkpoint_every"]) == ([0], 500)
    assert graph["train/robosuite-round/mlp/base"].config["train"]["hidden"] == [256, 256]


def _train_config(method: str, hidden: list[int], profile: str, seeds: list[int]) -> dict:
    train = {
        "model": "mlp",
        "hidden": hidden,
        "ensemble_size": 5,
        "epochs": 100,
        "checkpoint_every": 50,
        "batch_size": 512,
        "lr": 0.001,
        "seeds": seeds,
    }
    return {"method": method, "profile": profile, "train": train}


def test_the_report_says_which_policy_scored():
    base = _train_config("base", [256, 256], "cpu", [0, 1, 2])
    naive = _train_config("naive", [256, 256], "cpu", [0, 1, 2])
    before = (
        "Training: mlp: 5 member(s) × hidden [256, 256], 100 epochs (checkpoint every 50), "
        "batch 512, lr 0.001. The paper: 5 × [1024, 1024], 1000 epochs, every 200."
    )
    assert training_note({"a": base, "b": naive}) == before  # as before [scorer]
    big = _train_config("scorer", [1024, 1024], "paper", [0])
    note = training_note({"a": base, "s": big, "b": naive})
    assert note.startswith(before + " Scoring (the contrast sets and every D_new) by a policy")
    assert note.endswith(
        "mlp: 5 member(s) × hidden [1024, 1024], 100 epochs (checkpoint every 50), batch 512, "
        "lr 0.001, training profile paper, seed 0."
    )
    same = _train_config("scorer", [256, 256], "cpu", [0])
    assert training_note({"a": base, "s": same}) == before


TINY = """# tiny filtering study with a scorer of its own
[pipeline]
name = "tiny-scorer"
profile = "cpu"
seeds = [0]
models = ["mlp"]
methods = ["base", "filtered"]

[[task]]
name = "reach-pillar"
operators = ["conflict-right"]
base_episodes = 5
new_episodes = 4
holdout_episodes = 2
incompatible_operator = "conflict-over"
incompatible_episodes = 2

[train]
hidden = [8, 8]
ensemble_size = 2
epochs = 4
checkpoint_every = 4
batch_size = 128

[scorer]
profile = "cpu"
hidden = [16, 16]
ensemble_size = 2
epochs = 6
checkpoint_every = 6
batch_size = 128

[evaluate]
rollouts = 2
checkpoints = ["final"]
selection = "reported"

# tiny networks: whether the fit is trustworthy is not what this test checks
[thresholds]
force = true
"""


def test_tiny_run_scores_with_the_scorer_and_checks_its_training_demos(tmp_path):
    from elicit_jax.artifact import read_header, read_json
    from elicit_jax.pipeline.run import PipelineRunConfig, rebuild_report, run_pipeline
    from elicit_jax.pipeline.study_kinds import STUDY_KINDS

    spec = tmp_path / "tiny.toml"
    spec.write_text(TINY)
    out = tmp_path / "run"
    console = Console(file=open(os.devnull, "w"))  # noqa: SIM115
    outcome = run_pipeline(
        PipelineRunConfig(pipeline=str(spec), out=str(out), progress=False), console=console
    )
    assert "train/reach-pillar/mlp/scorer" in outcome.result.ran
    scorer = out / "policies/reach-pillar/mlp/scorer"
    assert read_header(scorer)["config"]["hidden"] == [16, 16]
    assert read_header(out / "policies/reach-pillar/mlp/base")["config"]["hidden"] == [8, 8]
    for scores in ("contrast", "new-conflict-right"):
        header = read_header(out / "scores/reach-pillar/mlp" / scores / "scores.parquet")
        assert Path(header["inputs"]["policy"]["path"]).name == "scorer"
    # the fit checks the training demos of the policy that scored (the scorer's: D_base)
    fitted = read_json(out / "thresholds/reach-pillar/mlp.json")["report"]
    check = fitted["training_check"]
    assert check["demos"] == 5 and "scorer" in check["source"]
    # the tiny scorer's fit rejects some of them, and the report's fit table says whose
    assert check["rejected"] > 0, "the planted case: the tiny fit rejects training demos"
    said = f"reject {check['rejected']} of the 5 training demos of the policy that scored (D_base)"
    assert any(said in p for p in fitted["trust"]["problems"])
    assert "base policy's" not in " ".join(fitted["trust"]["problems"])
    data = STUDY_KINDS["filtering"].report_data(out)
    (note,) = [n for n in data.notes if n.startswith("Training:")]
    assert "hidden [8, 8]" in note
    assert "by a policy of its own trained on D_base, not the base policy: mlp: 2 member(s)" in note
    assert "hidden [16, 16], 6 epochs" in note and "training profile cpu, seed 0" in note
    report = outcome.report_md.read_text()
    assert "Scoring (the contrast sets and every D_new)" in report
    assert said in report and "base policy's 5 own training" not in report
    md, _ = rebuild_report(out / "report", tmp_path / "rebuilt")  # from the folder alone
    assert md.read_text() == report
