"""Inputs and runs are never overwritten without a word; killed writes leave nothing behind;
an unwritable destination is named in the error."""

import os
import tempfile

import pytest
from fixtures_data import invoke, tiny_run, tiny_train_config

from elicit_jax.artifact import atomic_path, file_sha256
from elicit_jax.errors import ElicitError


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tiny_run(tmp_path_factory.mktemp("overwrite"))


def test_score_and_filter_refuse_to_write_over_their_input(work):
    demos = work / "demos.parquet"
    before = file_sha256(demos)
    r = invoke("score", "--policy", work / "run", "--demos", demos, "-o", demos)
    assert isinstance(r.exception, ElicitError) and "is the input" in str(r.exception)
    assert file_sha256(demos) == before
    r = invoke("score", "--policy", work / "run", "--demos", demos, "-o", work / "s.parquet")
    assert r.exit_code == 0, r.output
    for out in (demos, work / "s.parquet"):
        r = invoke(
            "filter", "--scores", work / "s.parquet", "--demos", demos, "-o", out,
            "--lambda", "0.4", "--eta", "0.05",
        )  # fmt: skip
        assert isinstance(r.exception, ElicitError) and "is the input" in str(r.exception)
    assert file_sha256(demos) == before
    # the per-episode sibling of a scores file is an output too: writing over the demos via
    # 'x.episodes.parquet' is caught as well
    r = invoke(
        "fit-thresholds", "--scores", work / "s.parquet", "--lambda", "0.4", "--eta", "0.05",
        "-o", work / "s.parquet",
    )  # fmt: skip
    assert isinstance(r.exception, ElicitError)


def test_train_refuses_to_replace_another_run(work, tmp_path):
    from elicit_jax.data.demos import read_demos
    from elicit_jax.policy.train import train_policy

    demos = read_demos(work / "demos.parquet")
    run = tmp_path / "run"
    train_policy(demos, tiny_train_config(), run, quiet=True)
    # the same config on the same data again: deterministic, so replacing it loses nothing
    train_policy(demos, tiny_train_config(), run, quiet=True)
    with pytest.raises(ElicitError, match=r"another config.*--overwrite"):
        train_policy(demos, tiny_train_config(seeds=(1,)), run, quiet=True)
    assert (run / "seed0").is_dir()  # the run is untouched
    train_policy(demos, tiny_train_config(seeds=(1,)), run, quiet=True, overwrite=True)
    assert (run / "seed1").is_dir() and not (run / "seed0").exists()
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "a.txt").write_text("mine")
    r = invoke(
        "train", "--demos", work / "demos.parquet", "--out", tmp_path / "notes", "--profile",
        "cpu", "--epochs", "1",
    )  # fmt: skip
    assert "not a training run" in str(r.exception)
    assert (tmp_path / "notes" / "a.txt").read_text() == "mine"


def test_temporaries_of_killed_writers_are_cleaned(tmp_path):
    from elicit_jax.output_rules import _temp_prefix

    out = tmp_path / "run"
    mine = _temp_prefix(out)  # .run.p<pid>-<host>.
    host = mine.split("-")[-1].rstrip(".")
    dead = tmp_path / f".run.p999999999-{host}.abc123.tmp"
    dead.mkdir()
    (dead / "half-written").write_text("x")
    old = tmp_path / ".run.old-999999999"
    old.mkdir()
    other_host = tmp_path / ".run.p999999999-00000000.zzz.tmp"
    other_host.mkdir()
    alive = tmp_path / f".run.p{os.getpid()}-{host}.live.tmp"
    alive.mkdir()
    with atomic_path(out) as tmp:
        tmp.mkdir()
    assert out.is_dir()
    assert not dead.exists() and not old.exists()
    assert other_host.exists() and alive.exists()  # never touch work that may be in progress


def test_unwritable_destination_names_the_output(tmp_path, monkeypatch):
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")
    with (
        pytest.raises(ElicitError, match="cannot write here") as e,
        atomic_path(blocker / "out.parquet"),
    ):
        pass
    assert str(blocker / "out.parquet") in str(e.value) and ".tmp" not in str(e.value)

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied", str(tmp_path / ".out.parquet.p1-x.tmp"))

    monkeypatch.setattr(tempfile, "mkdtemp", denied)
    with (
        pytest.raises(ElicitError, match="Permission denied") as e,
        atomic_path(tmp_path / "out.parquet"),
    ):
        pass
    assert str(e.value).startswith(str(tmp_path / "out.parquet"))
    assert ".tmp" not in str(e.value)
