"""Issue 27, items 1, 2, 4, 5: an output never deletes a directory, never replaces a file
without --overwrite, never lands inside an input; duplicate episodes are caught by content;
raw-unit thresholds are never applied to std-scaled scores without a word."""

import json

import numpy as np
import pytest
from fixtures_data import cli_ok, invoke, tiny_episodes, tiny_run

from elicit_jax.artifact import atomic_path, file_sha256, read_header
from elicit_jax.data.demos import from_episodes, read_demos, write_demos
from elicit_jax.errors import ElicitError


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    d = tiny_run(tmp_path_factory.mktemp("paths"))
    cli_ok("score", "--policy", d / "run", "--demos", d / "demos.parquet", "-o", d / "s.parquet",
           "--lambda", "0.4", "--eta", "0.05")  # fmt: skip
    return d


def _notes(parent):
    notes = parent / "notes"
    notes.mkdir(exist_ok=True)
    (notes / "a.txt").write_text("mine")
    return notes


def _commands(w, out):
    """Every file-writing command of the compatibility and demos steps, writing to ``out``."""
    demos, scores, run = w / "demos.parquet", w / "s.parquet", w / "run"
    t = ("--lambda", "0.4", "--eta", "0.05")
    return {
        "score": ("score", "--policy", run, "--demos", demos, "-o", out, *t),
        "filter": ("filter", "--scores", scores, "--demos", demos, "-o", out, *t),
        "fit-thresholds": ("fit-thresholds", "--scores", scores, "-o", out, *t),
        "map": ("map", "--scores", scores, "-o", out, *t),
        "demos select": ("demos", "select", demos, "--episodes", "0-1", "-o", out),
        "demos concat": ("demos", "concat", demos, demos, "-o", out, "--allow-duplicates"),
        "import": ("import", w / "x.npz", "-o", out),
        "make-example": ("make-example", "-o", out, "--demos-per-operator", "1"),
    }


def test_an_existing_directory_is_never_replaced(work, tmp_path):
    notes = _notes(tmp_path)
    for name, args in _commands(work, notes).items():
        for extra in ((), ("--overwrite",)):
            r = invoke(*args, *extra)
            assert isinstance(r.exception, ElicitError), (name, r.output, r.exception)
            assert "existing directory" in str(r.exception), (name, str(r.exception))
            assert (notes / "a.txt").read_text() == "mine", name
            assert sorted(p.name for p in notes.iterdir()) == ["a.txt"], name
    # train replaces only training runs, even with --overwrite
    r = invoke("train", "--demos", work / "demos.parquet", "--out", notes, "--profile", "cpu",
               "--epochs", "1", "--overwrite")  # fmt: skip
    assert "not a training run" in str(r.exception)
    assert (notes / "a.txt").read_text() == "mine"
    # a report goes over an earlier report only, never over another directory
    r = invoke("report", work / "run", "-o", notes)
    assert "existing directory" in str(r.exception) and (notes / "a.txt").exists()


def test_an_existing_file_needs_overwrite(work, tmp_path):
    out = tmp_path / "out.parquet"
    for name in ("score", "filter", "demos select", "demos concat"):
        out.write_text("precious")
        args = _commands(work, out)[name]
        r = invoke(*args)
        assert isinstance(r.exception, ElicitError) and "--overwrite" in str(r.exception), name
        assert out.read_text() == "precious", name
        cli_ok(*args, "--overwrite")
        assert read_header(out)["kind"] == "demos" or name == "score"
        out.unlink()
    # a sibling output (score's per-episode summary) counts too
    (tmp_path / "out.episodes.parquet").write_text("precious")
    r = invoke(*_commands(work, out)["score"])
    assert "already exists" in str(r.exception) and not out.exists()


def test_atomic_writes_never_turn_a_directory_into_a_file(tmp_path):
    notes = _notes(tmp_path)
    with pytest.raises(ElicitError, match="existing directory"), atomic_path(notes) as tmp:
        tmp.write_text("x")
    assert (notes / "a.txt").read_text() == "mine"


def test_an_output_inside_an_input_directory_is_refused(work):
    loss = work / "run" / "seed0" / "loss.parquet"
    before = file_sha256(loss)
    for args in (
        _commands(work, loss)["score"],
        (*_commands(work, work / "run" / "new.parquet")["score"], "--overwrite"),
    ):
        r = invoke(*args)
        assert "inside the input directory" in str(r.exception), r.exception
    assert file_sha256(loss) == before
    r = invoke("evaluate", "--policy", work / "run", "--rollouts", "1", "-o",
               work / "run" / "evals.parquet")  # fmt: skip
    assert "inside the input directory" in str(r.exception)


def test_concat_refuses_duplicate_episodes_unless_allowed(work, tmp_path):
    demos = work / "demos.parquet"
    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    cli_ok("demos", "select", demos, "--episodes", "0-3", "-o", a)
    cli_ok("demos", "select", demos, "--episodes", "2-5", "-o", b)
    r = invoke("demos", "concat", a, b, "-o", tmp_path / "ab.parquet")
    assert isinstance(r.exception, ElicitError)
    msg = str(r.exception)
    assert "2 episode(s) repeat" in msg and "--allow-duplicates" in msg
    assert f"episode 2 of {b} repeats episode 2 of {a}" in msg
    assert not (tmp_path / "ab.parquet").exists()
    # the same observations and actions under another operator label are still duplicates
    other = from_episodes(tiny_episodes()[:1], operators="someone-else")
    write_demos(tmp_path / "relabelled.parquet", other)
    r = invoke("demos", "concat", a, tmp_path / "relabelled.parquet", "-o", tmp_path / "x.parquet")
    assert "repeat" in str(r.exception)
    cli_ok("demos", "concat", a, b, "-o", tmp_path / "ab.parquet", "--allow-duplicates")
    kept = read_header(tmp_path / "ab.parquet")["config"]["duplicates_kept"]
    assert [(d["part"], d["episode"], d["of_part"], d["of_episode"]) for d in kept] == [
        (1, 2, 0, 2), (1, 3, 0, 3),
    ]  # fmt: skip
    # an export of that file leaves the second copies out, and says so
    r = cli_ok("export", tmp_path / "ab.parquet", "--format", "npz", "-o", tmp_path / "ab.npz")
    assert "left out 2 episode(s) identical" in r.output
    with np.load(tmp_path / "ab.npz") as z:
        assert len(z["lengths"]) == 6


def test_filter_base_drops_episodes_of_demos_identical_to_base(work, tmp_path):
    demos = work / "demos.parquet"
    base = tmp_path / "base.parquet"
    cli_ok("demos", "select", demos, "--episodes", "0,1", "-o", base)
    out = tmp_path / "f.parquet"
    r = cli_ok("filter", "--scores", work / "s.parquet", "--demos", demos, "--base", base,
               "-o", out, "--lambda", "1e9", "--eta", "1e-9")  # keeps every pair by M  # fmt: skip
    assert "dropped 2 episode(s) of --demos identical to --base episodes" in r.output
    assert "(6 -> 4 episodes; 2 episode(s) as duplicates of --base; the others:" in r.output
    got = read_demos(out)
    assert got.n_episodes == 6  # 2 of D_base + the 4 episodes of D_new it does not hold
    header = read_header(out)
    assert header["config"]["duplicates_of_base"] == {"0": 0, "1": 1}
    import pyarrow.parquet as pq

    log = pq.read_table(tmp_path / "f.dropped.parquet").to_pydict()
    assert set(log["reason"]) == {"duplicate of --base episode 0", "duplicate of --base episode 1"}
    assert set(log["episode"]) == {0, 1}


def test_std_scaled_scores_refuse_raw_unit_thresholds(work, tmp_path):
    run, demos = work / "run", work / "demos.parquet"
    score = ("score", "--policy", run, "--demos", demos, "--action-scale", "std")
    r = invoke(*score, "-o", tmp_path / "a.parquet", "--preset", "square-nut")
    assert isinstance(r.exception, ElicitError)
    assert "raw action units" in str(r.exception) and not (tmp_path / "a.parquet").exists()
    # a thresholds file fitted on raw-unit scores
    cli_ok("fit-thresholds", "--scores", work / "s.parquet", "--lambda", "0.4", "--eta", "0.05",
           "-o", tmp_path / "raw.json")  # fmt: skip
    assert json.loads((tmp_path / "raw.json").read_text())["action_scale"] == "none"
    r = invoke(*score, "-o", tmp_path / "a.parquet", "--thresholds", tmp_path / "raw.json")
    assert "--action-scale none scores" in str(r.exception)
    # no thresholds: scored, and M / accept-reject are said and recorded not to be verdicts
    r = cli_ok(*score, "-o", tmp_path / "std.parquet")
    assert "accept/reject in this file are not verdicts" in r.output
    assert read_header(tmp_path / "std.parquet")["thresholds_source"].startswith("raw-unit preset")
    # thresholds fitted on std-scaled scores apply to std-scaled scores only
    cli_ok("fit-thresholds", "--scores", tmp_path / "std.parquet", "--lambda", "2", "--eta", "1",
           "-o", tmp_path / "std.json")  # fmt: skip
    cli_ok(*score, "-o", tmp_path / "b.parquet", "--thresholds", tmp_path / "std.json")
    r = invoke("filter", "--scores", work / "s.parquet", "--demos", demos,
               "--thresholds", tmp_path / "std.json", "-o", tmp_path / "f.parquet")  # fmt: skip
    assert "--action-scale std scores" in str(r.exception)
    # live scoring (elicit, watch) is in raw units
    r = invoke("watch", tmp_path, "--policy", run, "--base-demos", demos,
               "--thresholds", tmp_path / "std.json", "--once")  # fmt: skip
    assert "do not apply to --action-scale none" in str(r.exception)
    r = invoke("serve", "--task", "reach-pillar", "--policy", run, "--base-demos", demos,
               "--thresholds", tmp_path / "std.json", "--sessions", tmp_path / "sessions",
               "--port", "0")  # fmt: skip
    assert "do not apply to --action-scale none" in str(r.exception)
    assert not (tmp_path / "sessions").exists()
    r = cli_ok(*score, "-o", tmp_path / "c.parquet", "--lambda", "2", "--eta", "1")
    assert "std-scaled units" in r.output
