"""Self-describing artifacts: a JSON header, content hashes, atomic writes.

Every artifact elicit-jax writes carries a header (``kind``, ``schema_version``, the config
that made it, the content hashes of its inputs, seeds, library versions). Parquet artifacts
keep it in the schema metadata under :data:`HEADER_KEY`; directory artifacts (checkpoints,
runs) keep it in ``artifact.json``.

The header's provenance block is made in :mod:`elicit_jax.provenance`, the atomic writes and
the output rule live in :mod:`elicit_jax.output_rules`, the hashes in
:mod:`elicit_jax.hashing`; this module re-exports them (the artifact API is one import).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.hashing import (  # noqa: F401  (re-exported: the artifact API)
    HEADER_KEY,
    VOLATILE_FIELDS,
    content_sha256,
    file_sha256,
    matches_recorded,
    stable_fields,
)
from elicit_jax.output_rules import (  # noqa: F401  (re-exported: the artifact API)
    atomic_path,
    atomic_paths,
    check_outputs,
    clean_stale_temporaries,
    foreign_files,
    refuse_foreign_files,
    refuse_overwriting_inputs,
)
from elicit_jax.provenance import (  # noqa: F401  (re-exported: the artifact API)
    PROVENANCE_KEY,
    code_commit,
    library_versions,
    provenance,
    provenance_line,
    recorded_now,
    runtime_settings,
)

DIR_HEADER = "artifact.json"


def now_utc() -> str:
    """The time to record as an artifact's ``created``: now, or ``SOURCE_DATE_EPOCH`` when
    that is set (reproducible-builds convention), so that identical runs can also give
    identical bytes."""
    return recorded_now()


def make_header(
    kind: str,
    schema_version: int,
    *,
    config: Mapping[str, Any] | None = None,
    inputs: Mapping[str, str | Path] | None = None,
    seed: int | list[int] | None = None,
    **fields: Any,
) -> dict[str, Any]:
    """Build an artifact header.

    Args:
      kind: artifact kind (``demos``, ``checkpoint``, ``scores``, ...).
      schema_version: version of that kind's layout.
      config: the config that produced the artifact (JSON-serialisable).
      inputs: name -> path of each input; stored as name -> {path, sha256}, the
        :func:`content_sha256` of each.
      seed: the PRNG seed, if any (a list: the seeds of a multi-seed artifact).
      **fields: kind-specific fields (shapes, names, ...).
    """
    header: dict[str, Any] = {
        "kind": kind,
        "schema_version": schema_version,
        "created": now_utc(),
        "config": dict(config or {}),
        "inputs": {
            name: {"path": str(p), "sha256": content_sha256(p)}
            for name, p in (inputs or {}).items()
        },
        "seed": seed,
        "versions": library_versions(),
        "runtime": runtime_settings(),
        PROVENANCE_KEY: provenance(),
    }
    header.update(fields)
    return header


def dumps(obj: Any) -> str:
    """JSON with numpy scalars and paths converted."""

    def default(o: Any) -> Any:
        if hasattr(o, "tolist"):
            return o.tolist()
        if isinstance(o, Path):
            return str(o)
        if hasattr(o, "__dataclass_fields__"):
            import dataclasses

            return dataclasses.asdict(o)
        raise TypeError(f"not JSON-serialisable: {type(o).__name__}")

    return json.dumps(obj, default=default, indent=1, sort_keys=True)


def holds_artifact(*kinds: str) -> Callable[[Path], bool]:
    """A ``replaceable`` test for :func:`check_outputs`: the directory's ``artifact.json``
    names one of ``kinds``."""

    def test(path: Path) -> bool:
        try:
            return read_header(path).get("kind") in kinds
        except ElicitError:
            return False

    return test


def write_json(path: str | Path, obj: Any) -> None:
    """Atomically write ``obj`` as JSON."""
    with atomic_path(path) as tmp:
        tmp.write_text(dumps(obj) + "\n")


def read_json(path: str | Path) -> Any:
    """Read JSON, turning a missing or malformed file into a one-line :class:`ElicitError`."""
    try:
        return json.loads(Path(path).read_text())
    except FileNotFoundError as e:
        raise ElicitError("file not found", path) from e
    except json.JSONDecodeError as e:
        raise ElicitError(f"malformed JSON ({e.msg} at line {e.lineno})", path) from e
    except UnicodeDecodeError as e:
        what = "a Parquet file" if _starts_with(path, b"PAR1") else "binary, not text"
        text = f"not a JSON file: it is {what} (byte {e.start} is not UTF-8)"
        raise ElicitError(text, path) from e


def _starts_with(path: str | Path, magic: bytes) -> bool:
    with open(path, "rb") as f:
        return f.read(len(magic)) == magic


def write_parquet(path: str | Path, table: Any, header: Mapping[str, Any]) -> None:
    """Atomically write a ``pyarrow.Table`` with ``header`` in its schema metadata."""
    import pyarrow.parquet as pq

    meta = dict(table.schema.metadata or {})
    meta[HEADER_KEY] = dumps(header).encode()
    table = table.replace_schema_metadata(meta)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")


def read_header(path: str | Path) -> dict[str, Any]:
    """Header of any artifact: a Parquet file or a directory with ``artifact.json``."""
    path = Path(path)
    if not path.exists():
        raise ElicitError("file not found", path)
    if path.is_dir():
        if not (path / DIR_HEADER).exists():
            raise ElicitError(f"not an elicit-jax artifact (no {DIR_HEADER})", path)
        return read_json(path / DIR_HEADER)
    if path.suffix == ".json":
        data = read_json(path)
        if not isinstance(data, dict) or "kind" not in data:
            raise ElicitError("not an elicit-jax artifact (no 'kind' field)", path)
        return data
    import pyarrow.parquet as pq

    try:
        meta = pq.read_schema(path).metadata or {}
    except Exception as e:  # pyarrow raises several types for non-Parquet input
        raise ElicitError(f"not a readable Parquet file ({type(e).__name__}: {e})", path) from e
    if HEADER_KEY not in meta:
        raise ElicitError("Parquet file has no elicit-jax header (was it written by us?)", path)
    try:
        return json.loads(meta[HEADER_KEY])
    except json.JSONDecodeError as e:
        raise ElicitError(f"malformed elicit-jax header: {e.msg}", path) from e


def read_artifact(
    path: str | Path,
    kind: str | tuple[str, ...],
    schema_version: int,
    *,
    what: str | None = None,
) -> dict[str, Any]:
    """The header of an artifact that must be of ``kind`` (one of them, for a tuple) and of a
    schema version this elicit-jax reads (``1 .. schema_version``): every artifact reader
    starts here. A header without a ``schema_version`` (written before versions were
    recorded) is read as version 1.

    Args:
      path: a Parquet file, a JSON artifact or a directory with ``artifact.json``.
      kind: the kind(s) the reader takes.
      schema_version: the newest version of that layout this elicit-jax understands.
      what: how the error names the expected artifact (default: the kind).

    Raises:
      ElicitError: one line naming the file: unreadable, another kind, or a missing, invalid
        or newer schema version.
    """
    header = read_header(path)
    check_artifact(header, path, kind, schema_version, what=what)
    return header


def check_artifact(
    header: Mapping[str, Any],
    path: str | Path,
    kind: str | tuple[str, ...],
    schema_version: int,
    *,
    what: str | None = None,
) -> None:
    """Refuse a header (read by :func:`read_artifact`, or by a reader that opens the file its
    own way) of another kind or of a schema version this elicit-jax does not read.

    Raises:
      ElicitError: as :func:`read_artifact`.
    """
    kinds = (kind,) if isinstance(kind, str) else tuple(kind)
    got = header.get("kind") if isinstance(header, Mapping) else type(header).__name__
    if got not in kinds:
        expected = what or " or ".join(f"'{k}'" for k in kinds)
        raise ElicitError(f"is a '{got}' artifact, expected {expected}", path)
    version = header.get("schema_version", 1)
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ElicitError(
            f"'{got}' artifact has no valid schema version ({version!r}); this elicit-jax "
            f"reads versions 1 to {schema_version}",
            path,
        )
    if version > schema_version:
        raise ElicitError(
            f"'{got}' schema version {version} is newer than this elicit-jax understands "
            f"({schema_version}); upgrade elicit-jax",
            path,
        )


def is_up_to_date(
    output: str | Path, config: Mapping[str, Any], inputs: Mapping[str, str | Path]
) -> bool:
    """True when ``output`` exists and was made from this config and these exact inputs."""
    try:
        header = read_header(output)
    except ElicitError:
        return False
    if header.get("config") != json.loads(dumps(dict(config))):
        return False
    recorded = header.get("inputs", {})
    if set(recorded) != set(inputs):
        return False
    return all(matches_recorded(recorded[k].get("sha256"), p) for k, p in inputs.items())
