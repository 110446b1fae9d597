"""Every artifact reader checks the artifact's kind and schema version through the one
``read_artifact`` (issue #48, item 4): a planted file of another kind, of a newer schema
version or of an invalid one is refused with one line naming the file."""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow as pa
import pytest

from elicit_jax.artifact import HEADER_KEY, read_artifact
from elicit_jax.errors import ElicitError


def _parquet(path: Path, header: dict) -> Path:
    import pyarrow.parquet as pq

    table = pa.table({"x": [1]}).replace_schema_metadata({HEADER_KEY: json.dumps(header)})
    pq.write_table(table, path)
    return path


def _json(path: Path, header: dict) -> Path:
    path.write_text(json.dumps(header))
    return path


def _dir(path: Path, header: dict, name: str = "artifact.json") -> Path:
    path.mkdir()
    (path / name).write_text(json.dumps({"seed": 0, "seed_dirs": {}, **header}))
    return path


def _demos(p):
    from elicit_jax.data.demos import read_demos

    return read_demos(p)


def _scores(p):
    from elicit_jax.compat.score_file import read_scores

    return read_scores(p)


def _episode_scores(p):
    from elicit_jax.curation.episodes import read_episode_scores

    return read_episode_scores(p)


def _quality(p):
    from elicit_jax.curation.quality import read_quality

    return read_quality(p)


def _trajectories(p):
    from elicit_jax.sim.trajectories import read_trajectories

    return read_trajectories(p)


def _thresholds(p):
    from elicit_jax.compat.thresholds import read_thresholds

    return read_thresholds(p)


def _selection(p):
    from elicit_jax.data.selection import read_selection

    return read_selection(p)


def _session(p):
    from elicit_jax.elicit.store import SessionStore

    return SessionStore(p).header()


def _policy(p):
    from elicit_jax.policy.loaded import load_policy

    return load_policy(p)


def _manifest(p):
    from elicit_jax.pipeline.gather import read_manifest

    return read_manifest(p)


# reader, its kind, how its file is laid out (the file the error names: path or its header)
READERS = [
    (_demos, "demos", "parquet"),
    (_scores, "scores", "parquet"),
    (_episode_scores, "episode-scores", "parquet"),
    (_quality, "quality", "parquet"),
    (_trajectories, "rollout-steps", "parquet"),
    (_thresholds, "thresholds", "json"),
    (_selection, "episode-list", "json"),
    (_session, "elicit-session", "dir"),
    (_policy, "checkpoint", "dir"),
    (_manifest, "pipeline-run", "run.json"),
]


def _plant(tmp_path: Path, layout: str, header: dict) -> tuple[Path, Path]:
    """The planted artifact (what the reader is given) and the file the error names."""
    if layout == "parquet":
        p = _parquet(tmp_path / "a.parquet", header)
        return p, p
    if layout == "json":
        p = _json(tmp_path / "a.json", header)
        return p, p
    if layout == "dir":
        d = _dir(tmp_path / "a", header)
        return d, d
    d = _dir(tmp_path / "a", header, name=layout)
    return d, d / layout


def _refused(reader, given: Path, named: Path, text: str) -> None:
    with pytest.raises(ElicitError) as e:
        reader(given)
    msg = str(e.value)
    assert msg.startswith(f"{named}: ") and text in msg and "\n" not in msg, msg


@pytest.mark.parametrize(("reader", "kind", "layout"), READERS, ids=[k for _, k, _ in READERS])
def test_each_reader_refuses_another_kind(tmp_path, reader, kind, layout):
    wrong = "report-data" if kind != "report-data" else "demos"
    given, named = _plant(tmp_path, layout, {"kind": wrong, "schema_version": 1})
    _refused(reader, given, named, f"is a '{wrong}' artifact, expected")


@pytest.mark.parametrize(("reader", "kind", "layout"), READERS, ids=[k for _, k, _ in READERS])
@pytest.mark.parametrize(
    ("version", "text"),
    [(99, "schema version 99 is newer than this elicit-jax understands"),
     ("2", "has no valid schema version ('2')"),
     (0, "has no valid schema version (0)")],
)  # fmt: skip
def test_each_reader_refuses_a_newer_or_invalid_schema_version(
    tmp_path, reader, kind, layout, version, text
):
    given, named = _plant(tmp_path, layout, {"kind": kind, "schema_version": version})
    _refused(reader, given, named, text)


def test_read_artifact_takes_its_kinds_and_versions(tmp_path):
    p = _json(tmp_path / "t.json", {"kind": "b", "schema_version": 2})
    assert read_artifact(p, ("a", "b"), 2)["kind"] == "b"
    _refused(lambda q: read_artifact(q, "b", 1), p, p, "'b' schema version 2 is newer")
    _refused(lambda q: read_artifact(q, "a", 2), p, p, "is a 'b' artifact, expected 'a'")
    # written before versions were recorded: read as version 1, as every reader did
    old = _json(tmp_path / "old.json", {"kind": "b"})
    assert read_artifact(old, "b", 1) == {"kind": "b"}
