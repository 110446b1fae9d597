"""Writing HDF5 files so that a full disk is a one-line error, never a corrupt file.

HDF5 (through h5py) reacts badly to a write that fails: a failed flush leaves its objects
half-closed, the garbage collector retries the flush, prints pages of tracebacks and may
crash the interpreter. So no h5py write here ever meets a full disk:

* :func:`write_new_hdf5` builds a new file in memory and writes its bytes with plain Python
  I/O into an atomic temporary (:func:`elicit_jax.artifact.atomic_path`): a full disk is an
  ``OSError`` there, the temporary is removed, nothing else is touched.
* :func:`edit_copy` edits a copy of an existing file (small additions: a mask), with the
  disk space the edit needs reserved *before* h5py opens it (HDF5 trims the reserve when it
  closes the file): a disk too full for the copy or the reserve fails in plain Python. The
  edit itself runs in a child process, so should HDF5 still fail, its state dies with it.

Every failure becomes an :class:`ElicitError` with HDF5's message cut to one line
(:func:`hdf5_reason`).
"""

from __future__ import annotations

import errno
import io
import json
import os
import pickle
import re
import shutil
import subprocess
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from elicit_jax.artifact import atomic_path
from elicit_jax.errors import ElicitError

RESERVE_BYTES = 1 << 20
"""Disk space reserved beyond the copy for an edit, on top of what the edit says it needs."""

_HDF5_ERRORS = (OSError, RuntimeError, ValueError, KeyError, TypeError)
"""What h5py raises when a write fails (its C errors map onto these)."""


def hdf5_reason(e: BaseException) -> str:
    """A one-line reason for an h5py / OS error: the system's message for its errno when it
    has one, or when HDF5's message names one (``No space left on device``), else the first
    line of HDF5's message without its low-level details."""
    if isinstance(e, ElicitError):
        return str(e)
    code = getattr(e, "errno", None)
    if isinstance(e, OSError) and code:
        return os.strerror(code)
    found = re.search(r"errno = (\d+)", str(e))
    if found and int(found.group(1)) > 0:
        return os.strerror(int(found.group(1)))
    text = (str(e).splitlines() or [type(e).__name__])[0]
    for cut in (" (file write failed", " (file read failed", ", errno = "):
        text = text.split(cut, 1)[0]
    return text.strip() or type(e).__name__


def write_new_hdf5(path: str | Path, build: Callable[[Any], None]) -> None:
    """Write a new HDF5 file at ``path`` (atomically): ``build(f)`` fills an open h5py file.

    The file is built in memory and its bytes written in one go, so a disk that fills, a
    file-size limit or any other write error leaves no file and no temporary behind.

    Raises:
      ElicitError: naming ``path``: the write failed and nothing was written.
    """
    import h5py

    buffer = io.BytesIO()
    try:
        with h5py.File(buffer, "w") as f:
            build(f)
    except ElicitError:
        raise
    except _HDF5_ERRORS as e:
        text = f"cannot build the HDF5 file ({hdf5_reason(e)}); nothing written"
        raise ElicitError(text, path) from e
    image = buffer.getbuffer()
    try:
        with atomic_path(path) as tmp, open(tmp, "wb") as out:
            out.write(image)
    except OSError as e:
        raise ElicitError(f"cannot write ({hdf5_reason(e)}; nothing written)", path) from e
    finally:
        image.release()


def reserve_space(path: Path, nbytes: int) -> None:
    """Allocate ``nbytes`` of disk space past the end of ``path`` (a full disk or a file-size
    limit fails here, in plain Python, instead of inside HDF5)."""
    size = path.stat().st_size
    fd = os.open(path, os.O_RDWR)
    try:
        try:
            os.posix_fallocate(fd, size, nbytes)
        except OSError as e:
            if e.errno not in (errno.EOPNOTSUPP, errno.EINVAL):  # the file system cannot
                raise
            os.lseek(fd, size, os.SEEK_SET)
            os.write(fd, b"\0" * nbytes)
        os.fsync(fd)
    finally:
        os.close(fd)


_CHILD = """
import json, os, pickle, sys
path, datasets = pickle.load(sys.stdin.buffer)
try:
    import h5py
    f = h5py.File(path, "r+")
    for name, (data, attrs) in datasets.items():
        if name in f:
            del f[name]
        d = f.create_dataset(name, data=data)
        for k, v in attrs.items():
            d.attrs[k] = v
    f.close()
except BaseException as e:
    sys.stdout.write(json.dumps({"errno": getattr(e, "errno", None), "text": str(e)}))
    sys.stdout.flush()
    os._exit(3)
"""
"""The child process of :func:`edit_copy`: it writes the datasets and exits at once (no
finalizers) when HDF5 fails, so a broken HDF5 state never reaches the parent."""


def edit_copy(
    source: Path,
    copy: Path,
    datasets: Mapping[str, tuple[Any, Mapping[str, str]]],
    needs: int = 0,
) -> None:
    """Copy ``source`` to ``copy`` and write ``datasets`` into the copy.

    The copy is made and the disk space the edit needs reserved in plain Python; HDF5 then
    writes the datasets in a child process, so that whatever a failing HDF5 write does
    (tracebacks from finalizers, a crash at exit) stays there and comes back as one line.

    Args:
      source: the file to copy (never opened for writing).
      copy: where the edited copy goes (a temporary of the caller's).
      datasets: HDF5 path -> (array, attributes) to write; a dataset already there is
        replaced.
      needs: the bytes the edit adds, about (reserved on disk with :data:`RESERVE_BYTES`
        more before HDF5 writes anything).

    Raises:
      ElicitError: the copy, the reserve or the edit failed; its message is the reason only
        (``source`` is untouched; the caller removes ``copy`` and names the file).
    """
    try:
        shutil.copyfile(source, copy)
        reserve_space(copy, RESERVE_BYTES + 4 * needs)
    except OSError as e:
        raise ElicitError(f"copying it: {hdf5_reason(e)}") from e
    payload = pickle.dumps((str(copy), {k: (v[0], dict(v[1])) for k, v in datasets.items()}))
    try:
        done = subprocess.run(
            [sys.executable, "-c", _CHILD], input=payload, capture_output=True, check=False
        )
    except OSError as e:
        raise ElicitError(f"cannot start the HDF5 writer: {hdf5_reason(e)}") from e
    if done.returncode == 0:
        return
    try:
        failure = json.loads(done.stdout.decode())
        code, text = failure.get("errno"), str(failure.get("text"))
        why = (
            os.strerror(code)
            if isinstance(code, int) and code > 0
            else hdf5_reason(RuntimeError(text))
        )
    except (ValueError, AttributeError):
        last = (done.stderr.decode(errors="replace").strip().splitlines() or [""])[-1]
        why = f"the HDF5 writer stopped (exit {done.returncode}) {last[:200]}".strip()
    raise ElicitError(f"writing its copy: {why}")
