"""Two writers of one output, and a kill between the renames of a pair of outputs: exactly
one writer wins and the other fails in one line; an output is never beside another run's
drop log."""

from __future__ import annotations

import os
import subprocess
import sys
import threading

import pytest
from fixtures_data import invoke, tiny_run

from elicit_jax import output_rules
from elicit_jax.artifact import atomic_path, file_sha256, read_header
from elicit_jax.errors import ElicitError


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A tiny run, its demos and their scores."""
    d = tiny_run(tmp_path_factory.mktemp("races"))
    r = invoke(
        "score", "--policy", d / "run", "--demos", d / "demos.parquet", "-o", d / "s.parquet"
    )
    assert r.exit_code == 0, r.output
    return d


def test_two_writers_of_a_new_file_exactly_one_wins(tmp_path):
    out = tmp_path / "same.parquet"
    both_written = threading.Barrier(2)
    results: dict[str, object] = {}

    def writer(name: str) -> None:
        try:
            with atomic_path(out) as tmp:
                tmp.write_text(name)
                both_written.wait(timeout=10)  # both began before either finished
            results[name] = "wrote"
        except ElicitError as e:
            results[name] = e

    threads = [threading.Thread(target=writer, args=(n,)) for n in ("a", "b")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    winners = [n for n, r in results.items() if r == "wrote"]
    assert len(winners) == 1, results
    loser = next(r for r in results.values() if r != "wrote")
    assert "created by another writer while this command ran" in str(loser)
    assert out.read_text() == winners[0]
    assert [p.name for p in tmp_path.iterdir()] == ["same.parquet"]


def test_score_loses_to_a_writer_that_finished_first(work, tmp_path, monkeypatch, cli):
    """Both ``score -o same.parquet`` checked that the output was free; the other finished
    first: this one fails in one line and leaves the other's file as it was."""
    out = tmp_path / "same.parquet"
    real = output_rules.sync_tree

    def the_other_writer_finishes(path):
        if not out.exists():
            out.write_bytes((work / "s.parquet").read_bytes())
        real(path)

    monkeypatch.setattr(output_rules, "sync_tree", the_other_writer_finishes)
    before_args = ("score", "--policy", work / "run", "--demos", work / "demos.parquet")
    code, _, err = cli(*before_args, "-o", out)
    assert code == 1
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "created by another writer while this command ran" in errors[0]
    assert err.endswith(errors[0] + "\n")
    assert file_sha256(out) == file_sha256(work / "s.parquet")
    # and its episode summary is not left beside the other writer's scores
    assert sorted(p.name for p in tmp_path.iterdir()) == ["same.parquet"]


KILL_AT_SECOND = """
import os, signal, sys
from pathlib import Path
out = Path(sys.argv[1]).resolve()
pair = {str(out), str(out.with_name(out.name.removesuffix(".parquet") + ".dropped.parquet"))}
seen = []
def killing(real):
    def move(src, dst, *args, **kwargs):
        d = str(Path(dst).resolve())
        if d in pair and d not in seen:
            seen.append(d)
            if len(seen) == 2:  # the second file of the pair is about to be put in place
                os.kill(os.getpid(), signal.SIGKILL)
        return real(src, dst, *args, **kwargs)
    return move
os.replace, os.rename, os.link = killing(os.replace), killing(os.rename), killing(os.link)
sys.argv = ["elicit-jax", *sys.argv[2:]]
from elicit_jax.cli import main
main()
"""


def test_a_kill_between_the_renames_of_filter_never_pairs_new_and_old(work, tmp_path):
    out = tmp_path / "f.parquet"
    log = tmp_path / "f.dropped.parquet"
    args = ["filter", "--scores", work / "s.parquet", "--demos", work / "demos.parquet", "-o", out]
    r = invoke(*args, "--lambda", "0.4", "--eta", "0.05")
    assert r.exit_code == 0, r.output
    old_log = file_sha256(log)
    env = {**os.environ, "ELICIT_JAX_LOG": str(tmp_path / "cli.log")}
    cmd = [sys.executable, "-c", KILL_AT_SECOND, str(out), *map(str, args)]
    cmd += ["--lambda", "0.2", "--eta", "0.05", "--overwrite"]
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == -9, done.stderr  # killed between the two renames
    # never the new output beside the old drop log: the output is missing until a re-run
    assert not (out.exists() and log.exists() and file_sha256(log) == old_log)
    assert not out.exists()
    r = invoke(*args, "--lambda", "0.2", "--eta", "0.05", "--overwrite")
    assert r.exit_code == 0, r.output
    assert read_header(out)["config"]["filter"] == read_header(log)["config"]
    assert read_header(log)["config"]["lambda_"] == 0.2
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_a_pair_is_put_in_place_whole_or_not_at_all(tmp_path):
    from elicit_jax.output_rules import atomic_paths

    log, out = tmp_path / "f.dropped.parquet", tmp_path / "f.parquet"
    log.write_text("old log")
    with (
        pytest.raises(ElicitError, match="created by another writer"),
        atomic_paths([log, out]) as (log_tmp, out_tmp),
    ):
        log_tmp.write_text("new log")
        out_tmp.write_text("new output")
        out.write_text("the other writer's output")  # made meanwhile
    assert log.read_text() == "old log"  # the new log was taken out, the old one put back
    assert out.read_text() == "the other writer's output"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.dropped.parquet", "f.parquet"]
    with atomic_paths([log, out]) as (log_tmp, out_tmp):
        log_tmp.write_text("new log")
        out_tmp.write_text("new output")
    assert (log.read_text(), out.read_text()) == ("new log", "new output")
