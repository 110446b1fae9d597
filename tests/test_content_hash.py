"""Issue 27, item 6: "same seed → same content". Headers carry wall-clock times (``created``,
``train_seconds``) and ``.npz`` members carry zip timestamps, so two identical runs differ in
bytes; their content hashes (what headers record for inputs) must not."""

import json

import numpy as np
import pytest
from fixtures_data import tiny_episodes, tiny_train_config

from elicit_jax import artifact
from elicit_jax.artifact import (
    VOLATILE_FIELDS,
    content_sha256,
    file_sha256,
    make_header,
    matches_recorded,
    read_header,
)
from elicit_jax.data.demos import from_episodes, write_demos


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    from elicit_jax.policy.train import train_policy

    d = tmp_path_factory.mktemp("twins")
    demos = from_episodes(tiny_episodes(), operators="base")
    for name in ("a", "b"):
        train_policy(demos, tiny_train_config(), d / name, quiet=True)
    return d / "a", d / "b"


def test_two_identical_trainings_have_one_content_hash(two_runs):
    a, b = two_runs
    # the bytes differ: wall-clock training time in every checkpoint header
    assert read_header(a / "seed0")["train_seconds"] != read_header(b / "seed0")["train_seconds"]
    assert file_sha256(a) != file_sha256(b)
    assert content_sha256(a) == content_sha256(b)
    for sub in ("seed0/artifact.json", "seed0/loss.parquet", "seed0/params/best.npz"):
        assert content_sha256(a / sub) == content_sha256(b / sub), sub
    # what a downstream header records for the policy (score's "inputs.policy.sha256")
    ha = make_header("scores", 1, inputs={"policy": a})["inputs"]["policy"]["sha256"]
    hb = make_header("scores", 1, inputs={"policy": b})["inputs"]["policy"]["sha256"]
    assert ha == hb


def test_the_content_hash_still_sees_every_real_change(two_runs, tmp_path):
    import shutil

    a, _ = two_runs
    c = tmp_path / "c"
    shutil.copytree(a, c)
    assert content_sha256(c) == content_sha256(a)
    best = c / "seed0" / "params" / "best.npz"
    with np.load(best) as z:
        params = {k: z[k].copy() for k in z.files}
    name = sorted(params)[0]
    params[name].flat[0] += 1e-6
    np.savez(best, **params)
    assert content_sha256(c) != content_sha256(a)
    shutil.rmtree(c)
    shutil.copytree(a, c)
    head = json.loads((c / "seed0" / "artifact.json").read_text())
    head["best_epoch"] = 1 + int(head["best_epoch"] or 0)
    (c / "seed0" / "artifact.json").write_text(json.dumps(head))
    assert content_sha256(c) != content_sha256(a)


def test_parquet_content_ignores_volatile_header_fields_only(tmp_path, monkeypatch):
    assert {"created", "train_seconds", "imported"} <= VOLATILE_FIELDS
    demos = from_episodes(tiny_episodes(n=2), operators="base")
    monkeypatch.setattr(artifact, "now_utc", lambda: "2026-01-01T00:00:00+00:00")
    write_demos(tmp_path / "a.parquet", demos)
    monkeypatch.setattr(artifact, "now_utc", lambda: "2026-06-30T12:34:56+00:00")
    write_demos(tmp_path / "b.parquet", demos)
    write_demos(tmp_path / "c.parquet", demos, config={"note": "another config"})
    a, b, c = (tmp_path / f"{n}.parquet" for n in "abc")
    assert file_sha256(a) != file_sha256(b)
    assert content_sha256(a) == content_sha256(b)
    assert content_sha256(a) != content_sha256(c)
    other = from_episodes(tiny_episodes(n=2, seed=1), operators="base")
    write_demos(tmp_path / "d.parquet", other)
    assert content_sha256(a) != content_sha256(tmp_path / "d.parquet")
    # headers written before content hashes recorded the bytes' hash: still recognised
    assert matches_recorded(file_sha256(a), a) and matches_recorded(content_sha256(a), b)
    assert not matches_recorded(file_sha256(a), b)


def test_source_date_epoch_gives_identical_bytes(tmp_path, monkeypatch):
    demos = from_episodes(tiny_episodes(n=2), operators="base")
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    write_demos(tmp_path / "a.parquet", demos)
    assert read_header(tmp_path / "a.parquet")["created"] == "2023-11-14T22:13:20+00:00"
    import time

    time.sleep(1.1)  # a later second: without SOURCE_DATE_EPOCH 'created' would differ
    write_demos(tmp_path / "b.parquet", demos)
    assert file_sha256(tmp_path / "a.parquet") == file_sha256(tmp_path / "b.parquet")
