"""The shipped ``robosuite`` study definition end to end on ``robosuite-square``, at tiny sizes:
every stage kind it uses (collect, train, score, fit, filter, DemInf, quality flags, Demo-SCORE
and CUPID rollouts of the naive policy, curate, evaluate on robosuite workers, map, report)
runs for real, and the report renders with a row for every method.

The definition is the shipped file with only its sizes shrunk (and one D_new operator, one
training seed, 5-step rollouts: robosuite steps in Python, and this must stay fast). In CI
(ELICIT_JAX_REQUIRE_ROBOSUITE=1) it must run: a missing robosuite is a failure there, a skip
elsewhere.
"""

from __future__ import annotations

import os
import sys
import tomllib
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from rich.console import Console

from elicit_jax.artifact import read_header
from elicit_jax.pipeline.run import PipelineRunConfig, run_pipeline
from elicit_jax.pipeline.spec import resolve_path

try:
    import robosuite  # noqa: F401

    HAVE_ROBOSUITE = True
except ModuleNotFoundError:
    HAVE_ROBOSUITE = False
if not HAVE_ROBOSUITE and os.environ.get("ELICIT_JAX_REQUIRE_ROBOSUITE") != "1":
    pytest.skip("robosuite extra not installed", allow_module_level=True)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from smoke_pipeline import to_toml

TINY_TASK = {
    "operators": ["mild"],
    "base_episodes": 2,
    "new_episodes": 3,  # quality flags need 3 episodes
    "holdout_episodes": 2,
    "incompatible_episodes": 2,
}
TINY_SECTIONS = {
    "train": {"hidden": [8], "ensemble_size": 2, "epochs": 4, "checkpoint_every": 2,
              "progress_every": 2, "batch_size": 32},
    # the shipped scorer (the paper's size) shrunk too, still unlike the compared policies
    "scorer": {"hidden": [12], "ensemble_size": 2, "epochs": 4, "checkpoint_every": 2,
               "progress_every": 2, "batch_size": 32},
    "evaluate": {"rollouts": 2, "horizon": 5, "workers": 2},
    "demo_score": {"rollouts": 2, "horizon": 5, "threads": 2, "classifier": {"steps": 50}},
    "cupid": {"rollouts": 2, "horizon": 5, "proj_dim": 32},
    "collect": {"threads": 2},
    # a tiny policy on 2 demos separates nothing: the thresholds are given (the fit stage
    # records them with its report), since whether a fit is trustworthy is not what this checks
    "thresholds": {"lambda": 0.4, "eta": 0.05},
}  # fmt: skip


def tiny_definition() -> dict:
    """The shipped definition, robosuite-square only, at tiny sizes (same methods)."""
    data = tomllib.loads(resolve_path("robosuite").read_text())
    square = next(t for t in data["task"] if t["name"] == "robosuite-square")
    data["task"] = [{**square, **TINY_TASK}]
    data["pipeline"] = {**data["pipeline"], "seeds": [0]}
    for name, table in TINY_SECTIONS.items():
        data[name] = {**data.get(name, {}), **table}
    data.pop("profiles", None)
    return data


def test_robosuite_study_runs_end_to_end_and_reports(tmp_path):
    spec = tmp_path / "tiny.toml"
    data = tiny_definition()
    spec.write_text(to_toml(data))
    out = tmp_path / "run"
    console = Console(file=open(os.devnull, "w"))  # noqa: SIM115
    outcome = run_pipeline(
        PipelineRunConfig(pipeline=str(spec), out=str(out), progress=False), console=console
    )
    ran = {s.split("/")[0] for s in outcome.result.ran}
    assert outcome.result.skipped == []
    # (curate stages' ids start with filter/: they write what a filter writes)
    assert ran == {"collect", "train", "score", "fit-thresholds", "filter", "deminf", "quality",
                   "demo-score", "cupid", "evaluate", "map", "report"}  # fmt: skip
    methods = data["pipeline"]["methods"]
    evals = sorted((out / "evals").rglob("*.parquet"))
    assert len(evals) == 1 + (len(methods) - 1)  # base + each method for the one operator
    for path in evals:
        header = read_header(path)
        assert header["config"]["task"] == "robosuite-square"
        frame = pq.read_table(path).to_pandas()
        assert len(frame) == 2 and (frame["length"] <= 5).all()
    # CUPID's rollouts were recorded on robosuite: its scores cover every D_new demo
    cupid = pq.read_table(out / "curation/robosuite-square/mlp/cupid-mild.parquet")
    assert cupid.num_rows == TINY_TASK["new_episodes"]
    report = (out / "report" / "report.md").read_text()
    assert "robosuite-square" in report and (out / "report" / "report.html").stat().st_size > 0
    assert "the one checkpoint evaluated per seed" in report  # final only: nothing chosen
    rolls = pq.read_table(out / "report" / "rollouts.parquet").to_pandas()
    assert set(rolls["method"]) == set(methods)
    # the contrast sets and D_new were scored by the scorer, trained on D_base
    scorer = out / "policies/robosuite-square/mlp/scorer"
    assert read_header(scorer)["config"]["hidden"] == [12]
    scores = read_header(out / "scores/robosuite-square/mlp/contrast/scores.parquet")
    assert Path(scores["inputs"]["policy"]["path"]).name == "scorer"
