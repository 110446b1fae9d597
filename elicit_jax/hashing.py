"""Content hashes of artifacts: by their bytes, or by what they hold.

:func:`file_sha256` hashes bytes. :func:`content_sha256` hashes what an artifact holds and
leaves out what differs between two identical runs (:data:`VOLATILE_FIELDS`: wall-clock
times and durations in headers, zip timestamps in ``.npz`` files); headers record it for
their inputs, so "same seed, same inputs" gives the same recorded hashes (docs/outputs.md).
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from pathlib import Path
from typing import Any

from elicit_jax.errors import ElicitError

HEADER_KEY = b"elicit_jax"
"""Key of the elicit-jax header in a Parquet artifact's schema metadata."""

VOLATILE_FIELDS: frozenset[str] = frozenset(
    {
        "created", "imported", "train_seconds", "seconds", "started", "elapsed", "time",
        "provenance", "reused_from",
    }
)  # fmt: skip
"""Header keys (at any depth) that differ between two identical runs: wall-clock times and
durations, the ``provenance`` block (code commit, command line, library versions) and a
pipeline's ``reused_from`` (an identical training copied): who made the artifact and how, not
what it holds. :func:`content_sha256` leaves them out, so that the same seed, config, inputs,
machine and thread count give the same content hash. A new header field of that sort is added
here, and only here."""


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    """Hash of a file's bytes, or of a directory (sorted relative paths and file hashes)."""
    path = Path(path)
    h = hashlib.sha256()
    if path.is_dir():
        for sub in sorted(p for p in path.rglob("*") if p.is_file()):
            h.update(str(sub.relative_to(path)).encode())
            h.update(file_sha256(sub).encode())
        return h.hexdigest()
    try:
        with open(path, "rb") as f:
            while block := f.read(chunk):
                h.update(block)
    except FileNotFoundError as e:
        raise ElicitError("file not found", path) from e
    return h.hexdigest()


def stable_fields(obj: Any, volatile: frozenset[str] = VOLATILE_FIELDS) -> Any:
    """``obj`` (parsed JSON) without the keys in ``volatile``, at any depth."""
    if isinstance(obj, dict):
        return {k: stable_fields(v, volatile) for k, v in obj.items() if k not in volatile}
    if isinstance(obj, list):
        return [stable_fields(v, volatile) for v in obj]
    return obj


def content_sha256(path: str | Path) -> str:
    """Hash of what an artifact holds, blind to when it was written.

    Two runs with the same seed, config and inputs (same machine and XLA thread count) give
    the same content hash even though their bytes differ:

    - a Parquet file with an elicit-jax header: its data pages, its Arrow schema (without
      metadata) and its header without :data:`VOLATILE_FIELDS`;
    - a ``.json`` file: its parsed content without :data:`VOLATILE_FIELDS`;
    - an ``.npz`` file: its arrays' names, dtypes, shapes and values (the zip entries'
      timestamps left out);
    - a directory: sorted relative paths and the content hash of each file;
    - any other file (robomimic HDF5, images, ...): its bytes, as :func:`file_sha256`.
    """
    path = Path(path)
    h = hashlib.sha256()
    if path.is_dir():
        for sub in sorted(p for p in path.rglob("*") if p.is_file()):
            h.update(str(sub.relative_to(path)).encode())
            h.update(content_sha256(sub).encode())
        return h.hexdigest()
    if not path.exists():
        raise ElicitError("file not found", path)
    try:
        if path.suffix == ".parquet":
            return _parquet_content_sha256(path) or file_sha256(path)
        if path.suffix == ".json":
            data = stable_fields(json.loads(path.read_text()))
            h.update(json.dumps(data, sort_keys=True).encode())
            return h.hexdigest()
        if path.suffix == ".npz":
            return _npz_content_sha256(path)
    except (ValueError, OSError, zipfile.BadZipFile):
        pass  # not what its name says: hashed by its bytes
    return file_sha256(path)


def matches_recorded(recorded: str | None, path: str | Path) -> bool:
    """True when ``recorded`` (an input's ``sha256`` in a header) is the hash of ``path``: its
    :func:`content_sha256`, or, for headers written before content hashes, its bytes'."""
    if not recorded:
        return False
    return recorded == content_sha256(path) or recorded == file_sha256(path)


def _parquet_content_sha256(path: Path) -> str | None:
    """Content hash of a Parquet artifact, or None when it has no elicit-jax header. Column
    chunks come before the footer, and only the footer holds the header."""
    import pyarrow.parquet as pq

    try:
        pf = pq.ParquetFile(path)
    except Exception:  # pyarrow raises several types for non-Parquet input
        return None
    meta = pf.schema_arrow.metadata or {}
    if HEADER_KEY not in meta:
        return None
    h = hashlib.sha256()
    h.update(json.dumps(stable_fields(json.loads(meta[HEADER_KEY])), sort_keys=True).encode())
    h.update(pf.schema_arrow.remove_metadata().to_string().encode())
    with open(path, "rb") as f:
        f.seek(-8, os.SEEK_END)
        footer = int.from_bytes(f.read(4), "little")
        left = os.path.getsize(path) - 8 - footer
        f.seek(0)
        while left > 0 and (block := f.read(min(left, 1 << 20))):
            h.update(block)
            left -= len(block)
    return h.hexdigest()


def _npz_content_sha256(path: Path) -> str:
    import numpy as np

    h = hashlib.sha256()
    with np.load(path, allow_pickle=False) as z:
        for name in sorted(z.files):
            a = np.ascontiguousarray(z[name])
            h.update(f"{name}|{a.dtype.str}|{a.shape}".encode())
            h.update(a.tobytes())
    return h.hexdigest()
