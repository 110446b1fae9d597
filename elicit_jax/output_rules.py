"""Writing outputs safely: atomic writes (a temporary sibling, flushed to disk, renamed into
place; a new path created exclusively, so of two concurrent writers one wins), pairs of files
put in place together, the clean-up of temporaries killed writers left, and the one rule for
every path a command writes (never over or inside an input or the artifact it belongs to;
never a directory; a file only with ``--overwrite``; a folder replaced whole only when it
holds nothing but what its writer wrote).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import platform
import re
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path

from elicit_jax.errors import ElicitError
from elicit_jax.runtime import process_alive


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


_DISK_FULL = frozenset({errno.ENOSPC, errno.EFBIG, errno.EDQUOT})
"""Errors only a write can meet: raised in a writer's block, they are about its output."""


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary sibling path; rename it onto ``path`` only if the block succeeds.

    Works for files and directories. On error the temporary is removed and ``path`` is
    untouched, so no half-written artifact is ever visible; temporaries a killed writer left
    behind are removed first (:func:`clean_stale_temporaries`). What is written is flushed to
    disk (``fsync``) before the rename, so the rename never publishes data still in flight.

    A path that did not exist when the block began is created exclusively: when another
    writer made it meanwhile (two commands writing the same output at once), this one fails
    and leaves the other's file alone; only a path that existed at the start (an output the
    caller was allowed to overwrite) is replaced. A destination that cannot be written
    (read-only directory, a full disk, a file in the way) is an :class:`ElicitError` naming
    ``path``, not the temporary; so is an existing directory where a file was written (a
    directory is only ever replaced by a directory).
    """
    path = Path(path)
    with _staged(path) as (target, existed):
        tmp = target.parent
        try:
            yield target
            if path.is_dir() and not path.is_symlink() and not target.is_dir():
                raise ElicitError(
                    "is an existing directory; refusing to replace it with a file "
                    "(nothing written)",
                    path,
                )
            try:
                sync_tree(target)
                _commit(target, path, existed)
            except OSError as e:
                raise ElicitError(f"cannot write ({e.strerror or e}; nothing written)", path) from e
            _sync_dir(path.parent)
        except OSError as e:
            if e.errno in _DISK_FULL or (e.filename and str(e.filename).startswith(str(tmp))):
                raise ElicitError(f"cannot write ({e.strerror or e}; nothing written)", path) from e
            raise


@contextlib.contextmanager
def atomic_paths(paths: Sequence[str | Path]) -> Iterator[list[Path]]:
    """:func:`atomic_path` for files that belong together (an output and its drop log):
    yield a temporary per path; when the block succeeds, put them all in place.

    The old files are first moved aside, then the new ones renamed in, in the order given
    (give the file readers look for last), then the old ones deleted. A kill in between
    never leaves a new file beside an old one of the pair: there are only new files and
    missing ones (the old ones, moved aside, are removed as stale temporaries by the next
    writer). A failure on the way (another writer made one of the paths meanwhile) takes the
    new files out again and puts the old ones back: all of the pair, or none of it.
    """
    paths = [Path(p) for p in paths]
    with contextlib.ExitStack() as stack:
        temps = [stack.enter_context(_staged(p)) for p in paths]
        yield [t for t, _ in temps]
        for target, _ in temps:
            if target.is_dir():
                raise ElicitError("atomic_paths writes files only", target)
        try:
            for target, _ in temps:
                sync_tree(target)
        except OSError as e:
            raise ElicitError(f"cannot write ({e.strerror or e}; nothing written)", paths[0]) from e
        aside: list[tuple[Path, Path]] = []
        for path in paths:
            if path.is_dir() and not path.is_symlink():
                raise ElicitError(
                    "is an existing directory; refusing to replace it with a file "
                    "(nothing written)",
                    path,
                )
        done: list[Path] = []
        try:
            for (_, existed), path in zip(temps, paths, strict=True):
                if existed and (path.exists() or path.is_symlink()):
                    old = path.with_name(f".{path.name}.old-{os.getpid()}")
                    os.replace(path, old)
                    aside.append((old, path))
            for (target, _), path in zip(temps, paths, strict=True):
                _commit(target, path, existed=False)
                done.append(path)
        except (OSError, ElicitError) as e:
            _roll_back(done, aside)
            if isinstance(e, ElicitError):
                raise
            raise ElicitError(f"cannot write ({e.strerror or e}; nothing written)", paths[0]) from e
        for old, _ in aside:
            old.unlink(missing_ok=True)
        for path in {p.parent for p in paths}:
            _sync_dir(path)


def _roll_back(done: list[Path], aside: list[tuple[Path, Path]]) -> None:
    """Undo a partial :func:`atomic_paths` commit: remove the new files put in place (each was
    created exclusively, so it is this writer's) and move the old ones back."""
    for path in done:
        with contextlib.suppress(OSError):
            path.unlink()
    for old, path in aside:
        with contextlib.suppress(OSError):
            os.replace(old, path)


@contextlib.contextmanager
def _staged(path: Path) -> Iterator[tuple[Path, bool]]:
    """A temporary directory beside ``path`` (removed on exit) and whether ``path`` existed."""
    existed = path.exists() or path.is_symlink()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        clean_stale_temporaries(path)
        tmp = Path(tempfile.mkdtemp(prefix=_temp_prefix(path), suffix=".tmp", dir=path.parent))
    except OSError as e:
        raise ElicitError(f"cannot write here ({e.strerror or e})", path) from e
    try:
        yield tmp / path.name, existed
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _commit(target: Path, path: Path, existed: bool) -> None:
    """Rename ``target`` onto ``path``: exclusively when ``path`` did not exist at the start."""
    if not existed:
        if target.is_dir():
            if path.exists() or path.is_symlink():
                raise _appeared(path)
            os.rename(target, path)
            return
        try:
            os.link(target, path)  # fails if path exists: create-exclusive
            return
        except FileExistsError as e:
            raise _appeared(path) from e
        except OSError as e:
            if e.errno not in (errno.EPERM, errno.ENOTSUP, errno.EXDEV, errno.EMLINK):
                raise
            if path.exists() or path.is_symlink():  # no hard links here: check, then rename
                raise _appeared(path) from e
    if path.is_dir() and not path.is_symlink():
        old = path.with_name(f".{path.name}.old-{os.getpid()}")
        os.replace(path, old)
        os.replace(target, path)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(target, path)


def _appeared(path: Path) -> ElicitError:
    return ElicitError(
        "was created by another writer while this command ran; it is left as that writer "
        "made it and nothing was written (run again with --overwrite to replace it)",
        path,
    )


def sync_tree(path: Path) -> None:
    """``fsync`` a file, or every file under a directory (and the directories themselves)."""
    if path.is_symlink() or not path.exists():
        return
    if path.is_dir():
        for root, _, files in os.walk(path):
            for name in files:
                sync_tree(Path(root) / name)
            _sync_dir(Path(root))
        return
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _sync_dir(path: Path) -> None:
    """Best-effort ``fsync`` of a directory (makes a rename in it durable; some file systems
    cannot, which is no reason to fail a write that already happened)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


_DIR_HEADER = "artifact.json"
"""The header file of a directory artifact (``elicit_jax.artifact.DIR_HEADER``)."""


def enclosing_artifacts(path: Path) -> list[Path]:
    """The directory artifacts ``path`` lies in: each ancestor holding an ``artifact.json``
    (a checkpoint's training run, a session's folder)."""
    return [a for a in path.parents if (a / _DIR_HEADER).is_file()]


def refuse_overwriting_inputs(
    outputs: Iterable[str | Path], inputs: Iterable[str | Path | None]
) -> None:
    """Raise when an output would replace an input, a directory holding one, or a file
    inside an input directory (a run, a LeRobot dataset) or inside the artifact directory
    an input belongs to (``runs/base/artifact.json`` when the input is ``runs/base/seed0``).

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
            for a in enclosing_artifacts(i):
                if a in o.parents:
                    raise ElicitError(
                        f"refusing to write here: this path is inside {a}, the artifact the "
                        f"input {i} belongs to; choose an output outside it",
                        out,
                    )


def _is_temporary(name: str) -> bool:
    """``name`` is one of this module's temporaries (``.<target>.p<pid>-<host>.*.tmp``,
    ``.<target>.old-<pid>``): written by elicit-jax, whatever the folder."""
    return name.startswith(".") and any(
        _TEMP_SUFFIX.match(name[i + 1 :]) for i, c in enumerate(name) if c == "." and i > 0
    )


def foreign_files(directory: str | Path, own: Callable[[str], bool]) -> list[str]:
    """What in ``directory`` its writer did not write: files (and empty folders, with a
    trailing ``/``) whose relative POSIX path ``own`` does not claim, sorted. Temporaries of
    :func:`atomic_path` (a killed writer's) are elicit-jax's own wherever they are."""
    root = Path(directory)
    found = []
    for base, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if not _is_temporary(d)]
        rel = Path(base).relative_to(root).as_posix()
        prefix = "" if rel == "." else rel + "/"
        found += [prefix + f for f in files if not own(prefix + f) and not _is_temporary(f)]
        if not dirs and not files and prefix and not own(prefix):
            found.append(prefix)
    return sorted(found)


def refuse_foreign_files(directory: str | Path, own: Callable[[str], bool], writer: str) -> None:
    """Raise unless everything in ``directory`` was written by ``writer`` (``own`` claims
    it): an artifact directory is replaced whole, so anything else in it would be lost.

    Raises:
      ElicitError: naming the directory and the first files in the way.
    """
    foreign = foreign_files(directory, own)
    if foreign:
        shown = ", ".join(foreign[:4]) + (
            f" and {len(foreign) - 4} more" if len(foreign) > 4 else ""
        )
        raise ElicitError(
            f"holds files {writer} did not write ({shown}); elicit-jax replaces only its own "
            "files: move them out of the folder, or choose another output",
            directory,
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
