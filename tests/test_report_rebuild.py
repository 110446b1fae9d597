"""Raw results kept in the report folder: held-out checkpoint selection by hand, provenance in
every header and report, and ``report --rebuild`` recomputing a study's report byte for byte
from its folder alone (the run directory deleted)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from elicit_jax.artifact import make_header, read_header, read_json, write_parquet
from elicit_jax.cli.app import app
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.evidence import (
    DATA_FILE,
    ROLLOUTS_FILE,
    cell_frame,
    result_rows_of,
    selection_lines,
    selection_meta,
)
from elicit_jax.pipeline.plan import build_graph
from elicit_jax.pipeline.run import rebuild_report, render_run_report, write_manifest
from elicit_jax.pipeline.spec import load_spec
from elicit_jax.pipeline.study_kinds import STAGE_KINDS
from elicit_jax.pipeline.tables import selection_label

SPEC = """# a tiny study: two methods, two training seeds, held-out checkpoint selection (default)
[pipeline]
name = "tiny-evidence"
profile = "cpu"
seeds = [0, 1]
models = ["mlp"]
methods = ["base", "naive"]

[[task]]
name = "reach-pillar"
operators = ["conflict-right"]
base_episodes = 4
new_episodes = 4
holdout_episodes = 2
incompatible_operator = "conflict-over"
incompatible_episodes = 2

[train]
hidden = [8, 8]
epochs = 4
checkpoint_every = 2

[evaluate]
rollouts = 4
"""


def _rollouts(successes: dict[tuple[int, int, str], list[bool]]) -> pd.DataFrame:
    """An evaluate stage's Parquet rows: (training seed, evaluation seed, checkpoint) → the
    successes of its rollouts."""
    parts = []
    for (seed, eval_seed, ckpt), wins in successes.items():
        n = len(wins)
        parts.append(
            pd.DataFrame(
                {
                    "policy": "p",
                    "seed": np.int32(seed),
                    "checkpoint": ckpt,
                    "rollout": np.arange(n, dtype=np.int32),
                    "init_seed": np.int64(eval_seed * 100_000) + np.arange(n),
                    "success": np.asarray(wins, bool),
                    "length": np.where(wins, 40, 100).astype(np.int32),
                    "eval_seed": np.int32(eval_seed),
                }
            )
        )
    return pd.concat(parts, ignore_index=True)


def _write_eval(path: Path, frame: pd.DataFrame) -> None:
    import pyarrow as pa

    path.parent.mkdir(parents=True, exist_ok=True)
    header = make_header("rollouts", 1, seed=0)
    write_parquet(path, pa.Table.from_pandas(frame, preserve_index=False), header)


def _config(selection: str) -> dict:
    meta = selection_meta({"selection": selection}, 0)
    return {"evaluate": {"task": "reach-pillar", "seed": 0}, "model": "mlp", "method": "naive",
            "operator": "op", **meta}  # fmt: skip


# Checkpoint "20" is best on the selection seed (100): 3/4 against 1/4; on the reported seed
# (0) it wins 1/4 and checkpoint "40" wins 4/4.
HAND = {
    (0, 100, "20"): [True, True, True, False],
    (0, 100, "40"): [True, False, False, False],
    (0, 0, "20"): [True, False, False, False],
    (0, 0, "40"): [True, True, True, True],
}


def test_heldout_selection_chooses_on_one_seed_and_reports_another(tmp_path):
    path = tmp_path / "e.parquet"
    _write_eval(path, _rollouts(HAND))
    (held,) = result_rows_of(cell_frame(_config("heldout"), path))
    assert held.checkpoint == "20" and held.success == pytest.approx(0.25)
    assert held.select_success == pytest.approx(0.75) and held.eval_seeds == (0, 100)
    assert held.n_rollouts == 4 and held.selection == "heldout"
    # the paper's rule: the best on the reported rollouts themselves (biased upwards)
    (paper,) = result_rows_of(cell_frame(_config("reported"), path))
    assert paper.checkpoint == "40" and paper.success == pytest.approx(1.0)
    # one checkpoint evaluated (e.g. checkpoints = ["final"]): nothing was chosen, and the
    # report says so instead of calling the number a maximum
    only = {k: v for k, v in HAND.items() if k[2] == "20"}
    _write_eval(path, _rollouts(only))
    for rule in ("reported", "heldout"):
        (one,) = result_rows_of(cell_frame(_config(rule), path))
        assert one.selection == "single" and one.success == pytest.approx(0.25)
    assert selection_label([one]) == "the one checkpoint evaluated per seed"
    assert selection_lines([one])[0].startswith("**Checkpoint: the only one evaluated.**")


def test_selection_is_validated():
    assert selection_meta({}, 0) == {"selection": "heldout", "select_seed": 100}
    with pytest.raises(ElicitError, match="select_seed must differ"):
        selection_meta({"select_seed": 3}, 3)
    with pytest.raises(ElicitError, match="selection must be one of"):
        selection_meta({"selection": "best"}, 0)


def _tiny_run(tmp_path: Path, text: str = SPEC) -> Path:
    """A study's run directory: the real plan and manifest; each evaluate stage's Parquet
    holds made-up rollouts (its successes depend on method, seed and checkpoint)."""
    spec_path = tmp_path / "tiny.toml"
    spec_path.write_text(text)
    spec = load_spec(spec_path)
    graph = build_graph(spec, STAGE_KINDS.resolve)
    run = tmp_path / "run"
    run.mkdir()
    write_manifest(run, spec, graph)
    rng = np.random.default_rng(7)
    for stage in graph:
        if stage.kind != "evaluate":
            continue
        cfg = stage.config
        assert cfg["selection"] == "heldout" and cfg["select_seed"] == 100  # the default
        seeds = (cfg["select_seed"], cfg["evaluate"]["seed"])
        cells = {
            (s, e, c): list(rng.random(4) < 0.5)
            for s in cfg["seeds"]
            for e in seeds
            for c in ("2", "4", "best")
        }
        _write_eval(run / stage.output, _rollouts(cells))
    return run


def test_report_rebuilds_byte_for_byte_from_its_folder_alone(tmp_path):
    run = _tiny_run(tmp_path)
    (tmp_path / "findings.md").write_text("### What we read\n\nNaive is made up here.\n")
    md, _ = render_run_report(run, tmp_path / "report", tmp_path / "findings.md")
    folder = md.parent
    shutil.rmtree(run)  # the run directory is gone: only the report folder is left
    text = md.read_text()
    lines = text.splitlines()
    assert lines[2].startswith("Provenance: code `") and "command `" in lines[2]
    assert "Seeds: training [0, 1], evaluation [0, 100]" in lines[4]
    assert "Checkpoint selection: held-out" in text and "ddof = 1" in text
    assert "Naive is made up here." in text
    header = read_header(folder / ROLLOUTS_FILE)
    assert header["training_seeds"] == [0, 1] and header["eval_seeds"] == [0, 100]
    assert header["provenance"]["commit"] and header["provenance"]["versions"]["numpy"]
    art = read_json(folder / "artifact.json")
    assert art["seed"] == 0 and set(art["inputs"]) == {ROLLOUTS_FILE, DATA_FILE}
    assert art["run"]["commit"] == art["provenance"]["commit"]

    before = {p.relative_to(folder): p.read_bytes() for p in folder.rglob("*") if p.is_file()}
    result = CliRunner().invoke(
        app, ["report", "--rebuild", str(folder), "-o", str(tmp_path / "b")]
    )
    assert result.exit_code == 0, (result.output, result.exception)
    rebuilt = tmp_path / "b"
    after = {p.relative_to(rebuilt): p.read_bytes() for p in rebuilt.rglob("*") if p.is_file()}
    assert set(after) == set(before)
    for name, content in before.items():
        if name != Path("artifact.json"):  # its own provenance (the rebuild's) differs
            assert after[name] == content, name
    assert read_json(rebuilt / "artifact.json")["rebuilt_from"] == str(folder)
    # in place, twice: still the same report
    rebuild_report(folder)
    assert (folder / "report.md").read_text() == text


def test_a_two_collection_study_rebuilds_its_across_collections_table(tmp_path):
    run = _tiny_run(tmp_path, SPEC + "\n[collections]\nseeds = [0, 1]\n")
    md, _ = render_run_report(run, tmp_path / "report")
    folder = md.parent
    shutil.rmtree(run)
    text = md.read_text()
    frame = pd.read_parquet(folder / ROLLOUTS_FILE)
    assert frame.columns[0] == "collection" and sorted(frame["collection"].unique()) == [0, 1]
    assert len(frame[frame["collection"] == 0]) == len(frame[frame["collection"] == 1])
    assert "## reach-pillar — mlp: across 2 collections [0, 1] × training seeds" in text
    assert "## collection 0: reach-pillar — mlp" in text and "## collection 1: " in text
    assert "Student's t over the 2 collections' means (df = 1)" in text and "Holm" in text
    assert "Sign agreement: in " in text and "collections agree in sign" in text
    assert "reach-pillar (collection 1)" in text  # rows of the later collection name it
    rebuild_report(folder, tmp_path / "again")
    for p in folder.rglob("*"):
        if p.is_file() and p.name != "artifact.json":
            assert (tmp_path / "again" / p.relative_to(folder)).read_bytes() == p.read_bytes(), p


def test_a_changed_raw_result_changes_the_rebuilt_report(tmp_path):
    import pyarrow.parquet as pq

    run = _tiny_run(tmp_path)
    md, _ = render_run_report(run, tmp_path / "report")
    folder = md.parent
    table = pq.read_table(folder / ROLLOUTS_FILE)
    frame = table.to_pandas()
    frame["success"] = True  # every rollout a success: every cell becomes 100.0
    import pyarrow as pa

    pq.write_table(
        pa.Table.from_pandas(frame, preserve_index=False).replace_schema_metadata(
            table.schema.metadata
        ),
        folder / ROLLOUTS_FILE,
    )
    rebuild_report(folder)
    assert "base only: 100.0 (0.0)" in (folder / "report.md").read_text()


def test_rebuild_of_a_folder_without_raw_results_is_a_one_line_error(tmp_path):
    result = CliRunner().invoke(app, ["report", "--rebuild", str(tmp_path)])
    assert result.exit_code != 0 and isinstance(result.exception, ElicitError)
    assert "cannot rebuild: no rollouts.parquet" in str(result.exception)


def _committed_studies() -> list[Path]:
    results = Path(__file__).resolve().parents[1] / "docs" / "results"
    return sorted(
        p.parent for p in results.glob(f"*/{ROLLOUTS_FILE}") if (p.parent / DATA_FILE).is_file()
    )


def test_every_committed_report_keeps_the_raw_results_it_rebuilds_from():
    results = Path(__file__).resolve().parents[1] / "docs" / "results"
    reports = sorted(md.parent for md in results.glob("*/report.md"))
    assert len(reports) >= 10
    assert reports == _committed_studies()


def test_no_committed_report_has_an_unknown_seed_empty_inputs_or_no_commit():
    results = Path(__file__).resolve().parents[1] / "docs" / "results"
    for record in sorted(results.glob("*/artifact.json")):
        head = read_json(record)
        where = record.parent.name
        assert isinstance(head["seed"], int) and head["training_seeds"], where
        assert set(head["inputs"]) == {ROLLOUTS_FILE, DATA_FILE}, where
        assert len(head["provenance"]["commit"]) == 40, where
        assert isinstance(head["provenance"]["dirty"], bool), where
        assert len(head["run"]["commit"]) == 40 and head["run"]["dirty"] is False, where


def test_every_committed_study_with_raw_results_rebuilds_byte_for_byte(tmp_path):
    studies = _committed_studies()
    assert [s.name for s in studies if s.name == "quickstart-cpu"] == ["quickstart-cpu"]
    for study in studies:
        out = tmp_path / study.name
        rebuild_report(study, out)
        files = {p.relative_to(study) for p in study.rglob("*") if p.is_file()}
        assert files == {p.relative_to(out) for p in out.rglob("*") if p.is_file()}
        for name in files - {Path("artifact.json")}:
            assert (out / name).read_bytes() == (study / name).read_bytes(), (study, name)
        run = read_json(study / "artifact.json")["run"]
        assert run["commit"] and run["command"] and read_json(out / "artifact.json")["run"] == run


def _study(tmp_path: Path):
    """A small elicitation study's data: two people, naive and informed sessions, made-up
    rollouts (the real gather is exercised by the tiny study in test_study_pipeline.py)."""
    from elicit_jax.pipeline.elicitation.gather import FilterCount, SessionData, StudyData

    rng = np.random.default_rng(3)
    frames = []
    cells = [("base", None), *[(c, p) for c in ("naive", "informed") for p in ("p0", "p1")]]
    for i, (cond, person) in enumerate(cells):
        path = tmp_path / f"e{i}.parquet"
        wins = {(s, e, c): list(rng.random(4) < 0.5) for s in (0, 1) for e in (0, 100)
                for c in ("2", "best")}  # fmt: skip
        _write_eval(path, _rollouts(wins))
        cfg = {**_config("heldout"), "method": cond, "operator": person}
        frames.append(cell_frame(cfg, path))
    rows = tuple(
        {"episode_kind": "demonstration", "index": k, "verdict": "accepted" if k else "rejected",
         "rule_verdict": "accept" if k else "reject", "length": 40 + k, "operator_steps": 40 + k,
         "fraction_incompatible": 0.1 / (k + 1), "intervention_rate": None, "interventions": 0}
        for k in range(3)
    )  # fmt: skip
    record = {"choices": {"route": "left"}, "start_choices": {}, "changes": [], "traits": {}}
    sessions = tuple(
        SessionData("reach-pillar", "mlp", c, p, f"person:mild,seed={p[1:]}", False, rows, record)
        for c in ("naive", "informed")
        for p in ("p0", "p1")
    )
    rollouts = pd.concat(frames, ignore_index=True)
    return StudyData(
        pipeline="tiny-study", profile="cpu", description="made up", run_dir="runs/x",
        spec_text="[pipeline]\n", results=tuple(result_rows_of(rollouts)), sessions=sessions,
        base_lengths={"reach-pillar": (41.0, 2.5, 4)},
        base_states={"reach-pillar": (np.linspace(0, 1, 46, dtype=np.float32).reshape(2, 23),)},
        thresholds={("reach-pillar", "mlp"): {"lambda": 0.3, "eta": 0.03, "method": "fit",
                                              "trust": None, "balanced_accuracy": 1.0}},
        filters=(FilterCount("reach-pillar", "mlp", "p0", 70, 100, 3, 3),),
        configs={"train": {}}, versions={"jax": "0"}, rollouts=rollouts,
        provenance={"commit": "abc", "dirty": False, "command": "elicit-jax x", "time": "t"},
    )  # fmt: skip


def test_an_elicitation_study_report_rebuilds_byte_for_byte(tmp_path):
    from elicit_jax.pipeline.elicitation.evidence import round_trip_study
    from elicit_jax.pipeline.elicitation.report import LAYOUT
    from elicit_jax.pipeline.report_folder import write_report

    md, _ = write_report(LAYOUT, round_trip_study(_study(tmp_path)), tmp_path / "study")
    folder = md.parent
    assert "Checkpoint selection: held-out" in md.read_text()
    assert "`elicit-jax report --rebuild <this folder>`" in md.read_text()
    rebuild_report(folder, tmp_path / "again")
    for p in folder.rglob("*"):
        if p.is_file() and p.name != "artifact.json":
            assert (tmp_path / "again" / p.relative_to(folder)).read_bytes() == p.read_bytes(), p


def test_provenance_line_names_every_commit_that_made_results():
    from elicit_jax.artifact import provenance_line

    prov = {
        "commit": "a" * 40,
        "dirty": False,
        "elicit_jax": "0.1.0",
        "versions": {"jax": "1"},
        "command": "elicit-jax pipeline run x",
        "time": "2026-01-01T00:00:00+00:00",
    }
    line = provenance_line({**prov, "result_commits": {"a" * 40: 3}})
    assert line == (
        "Provenance: code `aaaaaaaaaaaa`, elicit-jax 0.1.0 (jax 1); command "
        "`elicit-jax pipeline run x`; made 2026-01-01T00:00:00+00:00."
    )
    mixed = provenance_line({**prov, "result_commits": {"a" * 40: 3, "b" * 40 + "+dirty": 2}})
    assert mixed.endswith(
        "The evaluations were made at code `aaaaaaaaaaaa` (3), `bbbbbbbbbbbb+dirty` (2): cached "
        "stages carried the run across versions."
    )
    assert "not recorded" in provenance_line({})


def test_a_report_shortens_the_machines_absolute_paths_in_the_recorded_command():
    from elicit_jax.artifact import provenance_line

    prov = {
        "commit": "c" * 40,
        "dirty": False,
        "command": "elicit-jax pipeline run filtering --out /home/ann/runs/f-cpu --tasks 'a b'",
    }
    line = provenance_line(prov)
    assert "command `elicit-jax pipeline run filtering --out …/f-cpu --tasks 'a b'`" in line
    assert "/home/ann" not in line
    assert "command `elicit-jax quickstart`" in provenance_line(
        {**prov, "command": "elicit-jax quickstart"}
    )


def test_the_recorded_command_names_the_program(monkeypatch):
    from elicit_jax import provenance

    monkeypatch.delenv(provenance.COMMAND_ENV, raising=False)
    monkeypatch.setattr("sys.argv", ["/venv/bin/elicit-jax", "report", "runs/a b"])
    assert provenance.current_command() == "elicit-jax report 'runs/a b'"
    monkeypatch.setattr("sys.argv", ["-c", "report", "runs/x"])  # python -c CODE report runs/x
    assert provenance.current_command() == "python -c … report runs/x"
    monkeypatch.setenv(provenance.COMMAND_ENV, "elicit-jax pipeline run filtering")  # Ray task
    assert provenance.current_command() == "elicit-jax pipeline run filtering"


def test_a_report_names_no_folder_of_the_machine_that_ran_the_study(tmp_path):
    from elicit_jax.artifact import write_json

    text = SPEC.replace('methods = ["base", "naive"]', 'methods = ["base", "naive", "filtered"]')
    run = _tiny_run(tmp_path, text)  # an absolute run directory, as a Ray worker records it
    spec = load_spec(tmp_path / "tiny.toml")
    fit = next(s for s in build_graph(spec, STAGE_KINDS.resolve) if s.kind == "fit-thresholds")
    seed_dir = run / "policies" / "reach-pillar" / "mlp" / "base" / "seed0"
    write_json(
        run / fit.output,
        {
            "kind": "thresholds",  # read as what a fit stage writes
            "lambda": 0.5,
            "eta": 0.1,
            "method": "fit",
            "report": {
                "training_check": {
                    "demos": 4,
                    "rejected": 0,
                    "source": f"4 scored now under {seed_dir}",
                },
                "elsewhere": "/opt/other/place/x.parquet",
            },
        },
    )
    md, html = render_run_report(run, tmp_path / "report")
    data = (md.parent / DATA_FILE).read_text()
    for text in (md.read_text(), html.read_text(), data):
        assert str(tmp_path) not in text and "/opt/other" not in text
    assert "run directory `…/run`" in md.read_text()
    shown = read_json(md.parent / DATA_FILE)["data"]["thresholds"][0]["metrics"]
    assert (
        shown["training_check"]["source"]
        == "4 scored now under policies/reach-pillar/mlp/base/seed0"
    )
    assert shown["elsewhere"] == "…/x.parquet"


def test_every_committed_report_names_its_run_directory_as_a_relative_path():
    results = Path(__file__).resolve().parents[1] / "docs" / "results"
    named = {
        md.parent.name: line.split("run directory `", 1)[1].split("`", 1)[0]
        for md in results.glob("*/report.md")
        for line in md.read_text().splitlines()
        if "run directory `" in line
    }
    assert len(named) >= 9
    assert {k: v for k, v in named.items() if v.startswith(("/", "…"))} == {}
