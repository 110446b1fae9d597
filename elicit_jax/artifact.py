"""Self-describing artifacts: a JSON header, content hashes, atomic writes.

Every artifact elicit-jax writes carries a header (``kind``, ``schema_version``, the config
that made it, the content hashes of its inputs, seeds, library versions). Parquet artifacts
keep it in the schema metadata under :data:`HEADER_KEY`; directory artifacts (checkpoints,
runs) keep it in ``artifact.json``.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import hashlib
import json
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterable, Iterator, Mapping
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
from elicit_jax.runtime import available_cpus, process_alive

DIR_HEADER = "artifact.json"
PROVENANCE_KEY = "provenance"
"""The header key holding where an artifact came from (code commit, dirty tree, command line,
versions, time). Everything under it describes the making, not the content, so content hashes
of a header leave it out."""


def library_versions() -> dict[str, str]:
    """Versions of the libraries that shape results, without importing heavy modules."""
    return dict(_library_versions())


@functools.cache
def _library_versions() -> tuple[tuple[str, str], ...]:
    """Looked up once per process: reading package metadata takes milliseconds of Python
    (about 40 ms per artifact header before), and an installed version does not change under
    a running process."""
    from importlib import metadata

    out = []
    for name in ("elicit-jax", "jax", "jaxlib", "flax", "optax", "mujoco", "mujoco-mjx", "numpy"):
        with contextlib.suppress(metadata.PackageNotFoundError):
            out.append((name, metadata.version(name)))
    return tuple(out)


def code_commit() -> dict[str, Any]:
    """The git commit of the elicit-jax code that runs, and whether its tree had uncommitted
    changes (``{"commit": sha, "dirty": bool}``).

    Looked up once per process in the checkout that holds the imported package; an install
    from a wheel (no checkout) gives the commit its installer recorded, if any, else
    ``{"commit": "unknown (not a git checkout)", "dirty": None}``.
    """
    return dict(_code_commit())


@functools.cache
def _code_commit() -> tuple[tuple[str, Any], ...]:
    root = Path(__file__).resolve().parent.parent
    try:
        sha = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        status = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout
        return (("commit", sha), ("dirty", bool(status.strip())))
    except (OSError, subprocess.SubprocessError):
        return (("commit", _installed_commit()), ("dirty", None))


def _installed_commit() -> str:
    """The commit pip recorded for a VCS install (``direct_url.json``), if any."""
    from importlib import metadata

    with contextlib.suppress(metadata.PackageNotFoundError, ValueError, TypeError):
        text = metadata.distribution("elicit-jax").read_text("direct_url.json")
        commit = json.loads(text or "{}").get("vcs_info", {}).get("commit_id")
        if commit:
            return str(commit)
    return "unknown (not a git checkout)"


def provenance() -> dict[str, Any]:
    """Where an artifact made now comes from: code commit and dirty flag, the command line,
    the elicit-jax and library versions and the UTC time (kept under
    :data:`PROVENANCE_KEY` in every header)."""
    versions = library_versions()
    return {
        **code_commit(),
        "elicit_jax": versions.get("elicit-jax", "unknown"),
        "versions": versions,
        "command": shlex.join([Path(sys.argv[0]).name, *sys.argv[1:]]) if sys.argv else "",
        "python": platform.python_version(),
        "time": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
    }


def provenance_line(prov: Mapping[str, Any]) -> str:
    """One line saying where a result came from (the first line of every report)."""
    if not prov:
        return "Provenance: not recorded (made before elicit-jax recorded provenance)."
    dirty = prov.get("dirty")
    state = " (uncommitted changes)" if dirty else "" if dirty is False else " (tree unknown)"
    libs = ", ".join(
        f"{k} {v}" for k, v in dict(prov.get("versions", {})).items() if k != "elicit-jax"
    )
    made = dict(prov.get("result_commits") or {})
    own = str(prov.get("commit", "unknown")) + ("+dirty" if dirty else "")
    results = ""
    if made and set(made) != {own}:
        parts = ", ".join(
            f"`{c[:12]}{'+dirty' * c.endswith('+dirty')}` ({n})" for c, n in made.items()
        )
        results = (
            f" The evaluations were made at code {parts}: cached stages carried the run "
            "across versions."
        )
    return (
        f"Provenance: code `{str(prov.get('commit', 'unknown'))[:12]}`{state}, elicit-jax "
        f"{prov.get('elicit_jax', '?')} ({libs}); command `{prov.get('command', '?')}`; "
        f"made {prov.get('time', '?')}.{results}"
    )


def runtime_settings() -> dict[str, Any]:
    """Settings outside the config that can change numerics: XLA flags, the XLA CPU thread
    count (results are bit-identical only for the same machine and thread count), CPUs."""
    return {
        "XLA_FLAGS": os.environ.get("XLA_FLAGS", ""),
        "PJRT_NPROC": os.environ.get("PJRT_NPROC", ""),
        "cpus": available_cpus(),
        "machine": platform.machine(),
    }


def now_utc() -> str:
    """The time to record as an artifact's ``created``: now, or ``SOURCE_DATE_EPOCH`` when
    that is set (reproducible-builds convention), so that identical runs can also give
    identical bytes."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH", "").strip()
    when = (
        _dt.datetime.fromtimestamp(int(epoch), _dt.UTC)
        if epoch.isdigit()
        else _dt.datetime.now(_dt.UTC)
    )
    return when.isoformat(timespec="seconds")


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


def _host_tag() -> str:
    return hashlib.sha256(platform.node().encode()).hexdigest()[:8]


def _temp_prefix(path: Path) -> str:
    """``.<name>.p<pid>-<host>.``: temporaries say which process on which machine owns them."""
    return f".{path.name}.p{os.getpid()}-{_host_tag()}."


_TEMP_SUFFIX = re.compile(r"^(?:p(\d+)-([0-9a-f]{8})\..*\.tmp|old-(\d+))$")
"""What follows ``.<name>.`` in a temporary's name (see :func:`_temp_prefix`)."""


def clean_stale_temporaries(path: str | Path) -> list[Path]:
    """Remove temporaries of ``path`` left by killed writers; returns what was removed.

    Only temporaries written on this machine by processes that no longer exist are removed
    (``.<name>.p<pid>-<host>.*.tmp`` and ``.<name>.old-<pid>``), so a concurrent writer's
    work in progress is never touched.
    """
    path = Path(path)
    if not path.parent.is_dir():
        return []
    prefix = f".{path.name}."
    removed = []
    for p in path.parent.iterdir():
        m = _TEMP_SUFFIX.match(p.name[len(prefix) :]) if p.name.startswith(prefix) else None
        if not m:
            continue
        pid = int(m.group(1) or m.group(3))
        if m.group(2) not in (None, _host_tag()) or process_alive(pid):
            continue
        if p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
        removed.append(p)
    return removed


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary sibling path; rename it onto ``path`` only if the block succeeds.

    Works for files and directories. On error the temporary is removed and ``path`` is
    untouched, so no half-written artifact is ever visible; temporaries a killed writer left
    behind are removed first (:func:`clean_stale_temporaries`). A destination that cannot be
    written (read-only directory, a file in the way) is an :class:`ElicitError` naming
    ``path``, not the temporary; so is an existing directory where a file was written (a
    directory is only ever replaced by a directory).
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        clean_stale_temporaries(path)
        tmp = Path(tempfile.mkdtemp(prefix=_temp_prefix(path), suffix=".tmp", dir=path.parent))
    except OSError as e:
        raise ElicitError(f"cannot write here ({e.strerror or e})", path) from e
    target = tmp / path.name
    try:
        yield target
        if path.is_dir() and not path.is_symlink() and not target.is_dir():
            raise ElicitError(
                "is an existing directory; refusing to replace it with a file (nothing written)",
                path,
            )
        if path.is_dir() and not path.is_symlink():
            old = path.with_name(f".{path.name}.old-{os.getpid()}")
            os.replace(path, old)
            os.replace(target, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(target, path)
    except OSError as e:
        if e.filename and str(e.filename).startswith(str(tmp)):
            raise ElicitError(f"cannot write ({e.strerror or e})", path) from e
        raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def refuse_overwriting_inputs(
    outputs: Iterable[str | Path], inputs: Iterable[str | Path | None]
) -> None:
    """Raise when an output would replace an input, a directory holding one, or a file
    inside an input directory (a run, a LeRobot dataset).

    Args:
      outputs: paths about to be written.
      inputs: paths being read (``None`` entries are ignored).
    """
    ins = [Path(p).resolve() for p in inputs if p is not None]
    for out in outputs:
        o = Path(out).resolve()
        for i in ins:
            if o == i or o in i.parents:
                what = "is" if o == i else "holds"
                raise ElicitError(
                    f"refusing to write here: this path {what} the input {i}; choose another "
                    "output",
                    out,
                )
            if i in o.parents and i.is_dir():
                raise ElicitError(
                    f"refusing to write here: this path is inside the input directory {i}; "
                    "choose an output outside it",
                    out,
                )


def check_outputs(
    outputs: Iterable[str | Path | None],
    inputs: Iterable[str | Path | None] = (),
    *,
    overwrite: bool = False,
    replaceable: Callable[[Path], bool] | None = None,
) -> None:
    """The one rule for every path a command writes, checked before any work is done.

    - an output that is, holds or lies inside an input is refused
      (:func:`refuse_overwriting_inputs`);
    - an existing directory is refused, always, unless ``replaceable`` says it holds an
      artifact of the kind being written (and then only with ``overwrite``): a run, a folder
      of notes, a dataset is never deleted to make room for an output;
    - an existing file is refused unless ``overwrite``.

    Args:
      outputs: paths about to be written (``None`` entries are ignored).
      inputs: paths being read (``None`` entries are ignored).
      overwrite: the user passed ``--overwrite``.
      replaceable: for outputs that are directories, whether an existing directory holds
        an artifact of this kind that may be replaced.

    Raises:
      ElicitError: naming the output and what to do instead.
    """
    outs = [Path(p) for p in outputs if p is not None]
    refuse_overwriting_inputs(outs, inputs)
    for out in outs:
        if out.is_dir() and not out.is_symlink():
            if replaceable is None or not replaceable(out):
                raise ElicitError(
                    "is an existing directory; elicit-jax never replaces a directory with an "
                    "output: give a file path (e.g. inside it, or beside it)",
                    out,
                )
        elif not (out.exists() or out.is_symlink()):
            continue
        if not overwrite:
            raise ElicitError(
                "already exists; pass --overwrite to replace it, or choose another path", out
            )


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
