"""The smallest real pipeline end to end: collect → train → score → fit → filter → train →
evaluate → report on reach-pillar with tiny sizes; then a re-run does nothing and deleting
one artifact re-runs only its stage and what depends on it."""

from __future__ import annotations

import io
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from rich.console import Console

from elicit_jax.artifact import read_header
from elicit_jax.pipeline.run import (
    PipelineRunConfig,
    pipeline_status,
    print_results,
    run_pipeline,
)
from elicit_jax.pipeline.study_kinds import STUDY_KINDS

TINY = """# tiny end-to-end pipeline for the tests
[pipeline]
name = "tiny"
profile = "cpu"
seeds = [0]
models = ["mlp"]
methods = ["base", "naive", "filtered"]

[[task]]
name = "reach-pillar"
operators = ["conflict-right"]
base_episodes = 6
new_episodes = 6
holdout_episodes = 3
incompatible_operator = "conflict-over"
incompatible_episodes = 3

[train]
hidden = [16, 16]
ensemble_size = 3
epochs = 10
checkpoint_every = 5
progress_every = 5
batch_size = 128

[evaluate]
rollouts = 4

# a 16 x 16 model trained 10 epochs on 6 demos: whether its fit is trustworthy is luck of the
# draw, and not what these tests check
[thresholds]
force = true
"""


def run(spec: Path, out: Path):
    console = Console(file=open(os.devnull, "w"))  # noqa: SIM115
    cfg = PipelineRunConfig(pipeline=str(spec), out=str(out), progress=False)
    return run_pipeline(cfg, console=console)


def first_run(tmp_path: Path, text: str):
    """Write the pipeline ``text`` to ``tmp_path/tiny.toml`` and run it into ``tmp_path/run``
    for the first time (nothing skipped); returns the spec, the run directory, the outcome."""
    spec, out = tmp_path / "tiny.toml", tmp_path / "run"
    spec.write_text(text)
    outcome = run(spec, out)
    assert outcome.result.skipped == []
    return spec, out, outcome


@pytest.mark.slow
def _check_heldout_evaluation(spec: Path, out: Path, cell: str) -> None:
    """Every checkpoint rolled out on the selection seed, only the chosen one on the reported
    seed, and its rollouts exactly those it has when every checkpoint is rolled out there."""
    import dataclasses

    import pandas as pd

    from elicit_jax.pipeline.evidence import choose_checkpoint
    from elicit_jax.pipeline.plan import build_graph
    from elicit_jax.pipeline.spec import load_spec
    from elicit_jax.pipeline.study_kinds import STAGE_KINDS
    from elicit_jax.sim.evaluate import EvalConfig, evaluate_refs, expand_policies

    stage = build_graph(load_spec(spec), STAGE_KINDS.resolve)[f"evaluate/reach-pillar/mlp/{cell}"]
    raw = dict(stage.config["evaluate"])
    cfg = EvalConfig(**{**raw, "checkpoints": tuple(raw["checkpoints"])})
    frame = pd.read_parquet(out / stage.output)
    select = frame[frame["eval_seed"] == stage.config["select_seed"]]
    report = frame[frame["eval_seed"] == cfg.seed]
    assert select["checkpoint"].nunique() == 3  # epochs 5, 10 and the best-validation one
    (chosen,) = report["checkpoint"].unique()
    assert chosen == choose_checkpoint(select)[0]
    refs = expand_policies([f"{cell}={out / 'policies/reach-pillar/mlp' / cell}"], ["all"])
    every = evaluate_refs(refs, dataclasses.replace(cfg, seed=cfg.seed))
    alone = every[every["checkpoint"] == chosen]
    cols = ["seed", "rollout", "init_seed", "success", "length"]
    pd.testing.assert_frame_equal(
        alone[cols].reset_index(drop=True), report[cols].reset_index(drop=True)
    )


def test_tiny_pipeline_runs_skips_and_reruns_only_what_changed(tmp_path):
    spec, out, first = first_run(tmp_path, TINY)
    assert len(first.result.ran) == 16
    # the report: a result for every trained policy, the fit, the filter, the map
    data = STUDY_KINDS["filtering"].report_data(out)
    assert {(r.method, r.operator) for r in data.results} == {
        ("base", None),
        ("naive", "conflict-right"),
        ("filtered", "conflict-right"),
    }
    assert all(r.n_rollouts == 4 and 0.0 <= r.success <= 1.0 for r in data.results)
    assert sum(data.provenance["result_commits"].values()) == 3  # one per finished evaluation
    (fit,) = data.thresholds
    assert "conflict-over" in fit.incompatible and "held-out" in fit.compatible
    assert data.filters[0].pairs_total == pytest.approx(
        sum(r.n_episodes * r.mean_length for r in data.lengths if r.name == "new-conflict-right")
    )
    page = first.report_html.read_text()
    assert "data:image/png;base64," in page and "CPU profile" in page
    assert "M-Filtered" in first.report_md.read_text()
    assert read_header(out / "policies/reach-pillar/mlp/base")["config"]["hidden"] == [16, 16]
    _check_heldout_evaluation(spec, out, "naive-conflict-right")

    second = run(spec, out)
    assert second.result.ran == []
    shown = io.StringIO()
    print_results(out, Console(file=shown, width=200))
    assert "Naive − Base" in shown.getvalue() and "(1 seed)" in shown.getvalue()

    shutil.rmtree(out / "filtered/reach-pillar/mlp/filtered-conflict-right")
    status = pipeline_status(
        PipelineRunConfig(pipeline=str(spec), out=str(out)), console=Console(file=io.StringIO())
    )
    third = run(spec, out)
    assert status["to run"] == [
        "filter/reach-pillar/mlp/filtered/conflict-right",
        "train/reach-pillar/mlp/filtered/conflict-right",
        "evaluate/reach-pillar/mlp/filtered-conflict-right",
        "report",
    ]
    # the rebuilt filter output has the same content (only its 'created' time differs), so
    # what depends on it is still up to date: nothing downstream re-runs (content hashes)
    assert third.result.ran == ["filter/reach-pillar/mlp/filtered/conflict-right"]

    spec.write_text(TINY.replace("rollouts = 4", "rollouts = 3"))
    fourth = run(spec, out)
    assert sorted(fourth.result.ran) == sorted(
        [s for s in first.result.ran if s.startswith("evaluate/")] + ["report"]
    )


def test_cli_reports_a_bad_definition_in_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[pipeline]\nname = 'x'\nsedes = [0]\n")
    exe = Path(sys.executable).with_name("elicit-jax")
    proc = subprocess.run(
        [str(exe), "pipeline", "run", str(bad)], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines() == [
        f"error: {bad}: [pipeline]: unknown key(s) sedes (allowed: collect_seed, description, "
        "methods, models, name, profile, seeds, sizes)"
    ]


CURATION = (
    TINY.replace('name = "tiny"', 'name = "tiny-curation"').replace(
        'methods = ["base", "naive", "filtered"]',
        'methods = ["base", "naive", "filtered", "filtered-valley", "deminf", "deminf-matched",\n'
        '           "demo-score", "demo-score-matched"]',
    )
    + """
[deminf]
ks = [3]

[demo_score]
rollouts = 4

[demo_score.classifier]
steps = 100
eval_every = 50

[sensitivity]
points = 2
seeds = [7]
eval_seed = 1
"""
)


@pytest.mark.slow
def test_tiny_pipeline_with_curation_baselines_intervals_and_lambda_study(tmp_path):
    import numpy as np

    from elicit_jax.compat.measures import is_incompatible
    from elicit_jax.compat.score_file import read_scores
    from elicit_jax.compat.thresholds import read_thresholds, read_thresholds_header
    from elicit_jax.curation.episodes import read_episode_scores

    spec, out, first = first_run(tmp_path, CURATION)
    data = STUDY_KINDS["filtering"].report_data(out)
    methods = {
        *("base", "naive", "filtered", "filtered-valley"),
        *("deminf", "deminf-matched", "demo-score", "demo-score-matched"),
    }
    assert {r.method for r in data.results} == methods
    assert {(c.method, c.model) for c in data.curation} == {("deminf", None), ("demo-score", "mlp")}
    # matched: whole demos, lowest DemInf score first, until the M-filter's pair count is reached
    lam, eta = read_thresholds(out / "thresholds/reach-pillar/mlp.json").pair
    header, pairs = read_scores(out / "scores/reach-pillar/mlp/new-conflict-right/scores.parquet")
    assert header["thresholds_source"].startswith("the pipeline's threshold fit")  # after it
    budget = int(is_incompatible(pairs["likelihood"], pairs["novelty"], lam, eta).sum())
    assert int(np.asarray(pairs["incompatible"]).sum()) == budget
    deminf = read_episode_scores(out / "curation/reach-pillar/deminf-conflict-right.parquet")
    cum = np.cumsum(deminf.length[np.argsort(deminf.score, kind="stable")])
    want = int(cum[np.searchsorted(cum, budget)]) if budget else 0
    (row,) = [f for f in data.filters if f.method == "deminf-matched"]
    assert row.pairs_total - row.pairs_kept == want
    (own,) = [f for f in data.filters if f.method == "deminf"]
    assert own.episodes_total - own.episodes_kept == round(0.2 * 6)
    # the λ study: held-out seed 7, evaluation seed 1, λ at both ends of the fitted margin
    assert {r.seed for r in data.heldout} == {7}
    assert {(r.method, r.point) for r in data.heldout} == {
        ("base", None), ("naive", None), ("filtered", 0), ("filtered", 1)
    }  # fmt: skip
    fitted = read_thresholds_header(out / "thresholds/reach-pillar/mlp.json")
    lo, hi = fitted["report"]["lambda_range"]
    assert sorted(p.lambda_ for p in data.lambda_points) == pytest.approx([lo, hi])
    main_states = {r.init_states for r in data.results}
    assert len(main_states) == 1 and main_states.isdisjoint({r.init_states for r in data.heldout})
    md = first.report_md.read_text()
    assert "Naive − Base" in md and "DemInf (M's amount) − Naive" in md
    assert "λ sensitivity" in md and (out / "report/maps/lambda-sensitivity.png").exists()
    assert "Curation baselines" in md
    # the valley rule: λ inside the fitted margin, η as fitted
    valley = read_thresholds(out / "thresholds/reach-pillar/mlp-valley.json").lam
    assert lo <= valley <= hi and "valley rule" in md
    assert run(spec, out).result.ran == []


MODELS = """# tiny models study (MDN and LSTM ensembles), as pipelines/models.toml
[pipeline]
name = "tiny-models"
profile = "cpu"
seeds = [0, 1]
models = ["mdn", "lstm"]
methods = ["base", "naive"]

[[task]]
name = "reach-pillar"
operators = ["conflict-right"]
base_episodes = 5
new_episodes = 5
holdout_episodes = 2
incompatible_operator = "conflict-over"
incompatible_episodes = 2

[train]
hidden = [16, 16]
ensemble_size = 2
epochs = 4
checkpoint_every = 2
progress_every = 2
batch_size = 64

[evaluate]
rollouts = 3
"""


@pytest.mark.slow
def test_tiny_models_study_trains_and_evaluates_mdn_and_lstm(tmp_path):
    _, out, outcome = first_run(tmp_path, MODELS)
    data = STUDY_KINDS["filtering"].report_data(out)
    assert {(r.model, r.method, r.seed) for r in data.results} == {
        (m, k, s) for m in ("mdn", "lstm") for k in ("base", "naive") for s in (0, 1)
    }
    md = outcome.report_md.read_text()
    assert "reach-pillar: model comparison" in md and "Naive − Base" in md


@pytest.mark.slow
def test_tiny_pipeline_over_two_collections(tmp_path):
    """Every stage again on a second collection of the demo sets; D_new scored under the
    fitted thresholds, so the filter drops exactly the pairs its scores call incompatible."""
    import numpy as np
    import pandas as pd

    from elicit_jax.compat.measures import is_incompatible
    from elicit_jax.compat.score_file import read_scores
    from elicit_jax.compat.thresholds import read_thresholds

    collections = '\n[collections]\nseeds = [0, 1]\nmethods = ["base", "naive"]\n'
    spec, out, first = first_run(tmp_path, TINY + collections)
    assert len(first.result.ran) == 16 + 6
    data = STUDY_KINDS["filtering"].report_data(out)
    assert {(r.collection, r.method) for r in data.results} == {
        (0, "base"), (0, "naive"), (0, "filtered"), (1, "base"), (1, "naive"),
    }  # fmt: skip
    starts = [
        set(pd.read_parquet(out / f"data/{c}reach-pillar/base.parquet")["init_seed"])
        for c in ("", "c1/")
    ]
    assert starts[0] and starts[1] and not starts[0] & starts[1]  # another collection
    text = first.report_md.read_text()
    assert "across 2 collections [0, 1]" in text and "## collection 1: reach-pillar" in text
    assert [r.collection for r in data.thresholds] == [0]  # collection 1 filters nothing

    lam, eta = read_thresholds(out / "thresholds/reach-pillar/mlp.json").pair
    _, scores = read_scores(out / "scores/reach-pillar/mlp/new-conflict-right/scores.parquet")
    expected = is_incompatible(
        np.asarray(scores["likelihood"]), np.asarray(scores["novelty"]), lam, eta
    )
    assert np.array_equal(np.asarray(scores["incompatible"], bool), expected)
    header = read_header(out / "filtered/reach-pillar/mlp/filtered-conflict-right")
    assert header["pairs_dropped"] == int(expected.sum())
    assert run(spec, out).result.ran == []
