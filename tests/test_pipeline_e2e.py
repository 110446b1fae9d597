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
from elicit_jax.pipeline.gather import gather
from elicit_jax.pipeline.run import PipelineRunConfig, pipeline_status, run_pipeline

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
"""


def run(spec: Path, out: Path):
    console = Console(file=open(os.devnull, "w"))  # noqa: SIM115
    cfg = PipelineRunConfig(pipeline=str(spec), out=str(out), progress=False)
    return run_pipeline(cfg, console=console)


@pytest.mark.slow
def test_tiny_pipeline_runs_skips_and_reruns_only_what_changed(tmp_path):
    spec = tmp_path / "tiny.toml"
    spec.write_text(TINY)
    out = tmp_path / "run"
    first = run(spec, out)
    assert first.result.skipped == [] and len(first.result.ran) == 16
    # the report: a result for every trained policy, the fit, the filter, the map
    data = gather(out)
    assert {(r.method, r.operator) for r in data.results} == {
        ("base", None),
        ("naive", "conflict-right"),
        ("filtered", "conflict-right"),
    }
    assert all(r.n_rollouts == 4 and 0.0 <= r.success <= 1.0 for r in data.results)
    (fit,) = data.thresholds
    assert "conflict-over" in fit.incompatible and "held-out" in fit.compatible
    assert data.filters[0].pairs_total == pytest.approx(
        sum(r.n_episodes * r.mean_length for r in data.lengths if r.name == "new-conflict-right")
    )
    page = first.report_html.read_text()
    assert "data:image/png;base64," in page and "CPU profile" in page
    assert "M-Filtered" in first.report_md.read_text()
    assert read_header(out / "policies/reach-pillar/mlp/base")["config"]["hidden"] == [16, 16]

    second = run(spec, out)
    assert second.result.ran == []

    shutil.rmtree(out / "filtered/reach-pillar/mlp/filtered-conflict-right")
    status = pipeline_status(
        PipelineRunConfig(pipeline=str(spec), out=str(out)), console=Console(file=io.StringIO())
    )
    third = run(spec, out)
    assert status["to run"] == third.result.ran
    assert third.result.ran == [
        "filter/reach-pillar/mlp/filtered/conflict-right",
        "train/reach-pillar/mlp/filtered/conflict-right",
        "evaluate/reach-pillar/mlp/filtered-conflict-right",
        "report",
    ]

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
        "methods, models, name, profile, seeds)"
    ]
