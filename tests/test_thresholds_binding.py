"""Thresholds bound to what they were fitted for (issue #45 items 6, 7, 10, 11, 18): the
policy, the units, their own file's validity; every command that applies them says which it
used and where they came from; with SOURCE_DATE_EPOCH two runs write the same bytes."""

from __future__ import annotations

import json
import shutil
import time

import numpy as np
import pytest
from fixtures_data import cli_ok, invoke, tiny_run

from elicit_jax.compat.thresholds import read_thresholds
from elicit_jax.errors import ElicitError
from elicit_jax.policy.checkpoint import FILE_HASHES, file_hashes


@pytest.fixture(scope="module")
def d(tmp_path_factory):
    """A tiny run, a second policy (its parameters nudged: another policy, same shapes), the
    demos scored by each, and hand-set thresholds recorded on the first policy's scores."""
    d = tiny_run(tmp_path_factory.mktemp("binding"))
    shutil.copytree(d / "run", d / "other")
    best = d / "other" / "seed0" / "params" / "best.npz"
    with np.load(best) as z:
        arrays = {k: z[k] + np.float32(0.01) for k in z.files}
    np.savez(best, **arrays)
    # a new policy written consistently: its header records the nudged files' hashes
    seed = d / "other" / "seed0"
    header = json.loads((seed / "artifact.json").read_text())
    header[FILE_HASHES] = file_hashes(seed)
    (seed / "artifact.json").write_text(json.dumps(header))
    for run, out in (("run", "s.parquet"), ("other", "s_other.parquet")):
        cli_ok(*_score(d, run, out), "--lambda", "0.3", "--eta", "0.5")
    cli_ok("fit-thresholds", "--scores", d / "s.parquet", "--lambda", "0.3", "--eta", "0.5",
           "-o", d / "t.json")  # fmt: skip
    return d


def _score(d, run, out, *more):
    return ("score", "--policy", d / run, "--demos", d / "demos.parquet", "-o", d / out, *more)


def _filter(d, scores, out, *more):
    args = ("filter", "--scores", d / scores, "--demos", d / "demos.parquet", "-o", d / out)
    return invoke(*args, *more, "--overwrite")


def _refused(r, *names):
    assert isinstance(r.exception, ElicitError), (r.output, r.exception)
    msg = str(r.exception)
    assert "\n" not in msg and all(str(n) in msg for n in names), msg
    return msg


# --- item 6: a thresholds file names its policy; another policy's scores refuse it ----------


def test_a_thresholds_file_records_the_policy_its_scores_came_from(d):
    t = read_thresholds(d / "t.json")
    scores = json.loads((d / "t.json").read_text())
    assert t.policy is not None and len(t.policy) == 64
    assert scores["policy_sha256"] == t.policy
    from elicit_jax.artifact import read_header

    assert read_header(d / "s.parquet")["policy"]["policy_sha256"] == t.policy
    assert read_header(d / "s_other.parquet")["policy"]["policy_sha256"] != t.policy


def test_filter_map_and_score_refuse_another_policys_thresholds_without_force(d):
    t = d / "t.json"
    msg = _refused(_filter(d, "s_other.parquet", "f.parquet", "--thresholds", t), t, "s_other")
    assert "another policy" in msg and "--force" in msg
    assert not (d / "f.parquet").exists()
    r = invoke("map", "--scores", d / "s_other.parquet", "-o", d / "m1.png", "--thresholds", t)
    _refused(r, t, "s_other.parquet")
    r = invoke(*_score(d, "other", "s2.parquet", "--thresholds", t))
    _refused(r, t, d / "other")
    assert not (d / "s2.parquet").exists()
    r = _filter(d, "s_other.parquet", "f.parquet", "--thresholds", t, "--force")
    assert r.exit_code == 0, (r.output, r.exception)
    assert "another policy" in r.output and "applied anyway" in r.output
    # the policy they were fitted for: applied without a word of warning
    r = _filter(d, "s.parquet", "g.parquet", "--thresholds", t)
    assert r.exit_code == 0 and "another policy" not in r.output, r.output


def test_an_old_thresholds_file_without_its_policy_still_applies_with_a_warning(d, tmp_path):
    old = tmp_path / "old.json"
    data = json.loads((d / "t.json").read_text())
    del data["policy_sha256"]
    old.write_text(json.dumps(data))
    r = _filter(d, "s_other.parquet", "f.parquet", "--thresholds", old)
    assert r.exit_code == 0, (r.output, r.exception)
    assert "does not record its policy" in r.output and str(old) in r.output


# --- item 7: std scores' stand-in preset is not applied silently ----------------------------


def test_filter_and_map_refuse_the_stand_in_thresholds_of_std_scores(d):
    r = invoke(*_score(d, "run", "std.parquet", "--action-scale", "std"))
    assert r.exit_code == 0, (r.output, r.exception)
    msg = _refused(_filter(d, "std.parquet", "f.parquet"), "std.parquet")
    assert "not a verdict" in msg and "--thresholds" in msg
    _refused(invoke("map", "--scores", d / "std.parquet", "-o", d / "m2.png"), "std.parquet")
    r = _filter(d, "std.parquet", "f.parquet", "--force")
    assert r.exit_code == 0 and "applied anyway" in r.output, r.output
    r = _filter(d, "std.parquet", "h.parquet", "--lambda", "0.9", "--eta", "0.9")
    assert r.exit_code == 0 and "λ=0.9, η=0.9 from given" in r.output, r.output


# --- item 10: a thresholds file's numbers are numbers ---------------------------------------


@pytest.mark.parametrize(
    ("change", "text"),
    [
        ({"lambda": True}, "'lambda' must be a number, got True"),
        ({"lambda": "0.3"}, "'lambda' must be a number, got '0.3'"),
        ({"eta": float("nan")}, "'eta' must be a finite number > 0"),
        ({"lambda": float("inf")}, "'lambda' must be a finite number > 0"),
        ({"lambda": -0.3}, "'lambda' must be a finite number > 0"),
        ({"schema_version": 99}, "schema version 99"),
    ],
)
def test_bad_thresholds_files_are_refused_in_one_line(d, tmp_path, change, text):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({**json.loads((d / "t.json").read_text()), **change}))
    msg = _refused(_filter(d, "s.parquet", "f.parquet", "--thresholds", bad), bad)
    assert msg.startswith(f"{bad}: ") and text in msg


# --- item 18: which (λ, η), from where ------------------------------------------------------


def test_every_command_says_which_thresholds_it_applied_and_where_from(d):
    r = _filter(d, "s.parquet", "k.parquet")
    assert r.exit_code == 0, (r.output, r.exception)
    assert "thresholds: λ=0.3, η=0.5 from the values stored in" in r.output
    assert "s.parquet" in r.output and "pass --thresholds" in r.output
    r = _filter(d, "s.parquet", "l.parquet", "--thresholds", d / "t.json")
    assert f"thresholds: λ=0.3, η=0.5 from file {d / 't.json'}" in r.output
    r = invoke("map", "--scores", d / "s.parquet", "-o", d / "m.html")
    assert "from the values stored in" in r.output
    r = invoke(*_score(d, "run", "p.parquet", "--preset", "round-nut"))
    assert "thresholds: λ=0.35, η=0.05 from preset round-nut" in r.output


# --- item 11: SOURCE_DATE_EPOCH gives byte-identical scores and thresholds files ------------


def test_source_date_epoch_makes_scores_and_thresholds_byte_identical(d, tmp_path, monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    outs = []
    for k in range(2):
        if k:
            time.sleep(1.1)  # a wall-clock time would now differ
        cli_ok(*_score(d, "run", "e.parquet", "--lambda", "0.3", "--eta", "0.5", "--overwrite"))
        cli_ok("fit-thresholds", "--scores", d / "e.parquet", "--lambda", "0.3", "--eta", "0.5",
               "-o", d / "e.json", "--overwrite")  # fmt: skip
        names = ("e.parquet", "e.episodes.parquet", "e.json")
        outs.append([(d / n).read_bytes() for n in names])
    assert outs[0] == outs[1]
    header = json.loads((d / "e.json").read_text())
    assert header["provenance"]["time"] == header["created"] == "2023-11-14T22:13:20+00:00"


def test_demos_given_as_scores_are_named_as_such(d):
    r = _filter(d, "demos.parquet", "f.parquet")
    assert "is a 'demos' artifact, expected scores" in _refused(r, d / "demos.parquet")
