"""Where an artifact comes from: the code commit (and whether its tree was dirty), the
command line, library versions, the time and the runtime settings that can change numerics.

Every header :func:`elicit_jax.artifact.make_header` builds carries them under
:data:`PROVENANCE_KEY` (and ``versions``, ``runtime``); reports open with
:func:`provenance_line`.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import json
import os
import platform
import re
import shlex
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from elicit_jax.runtime import available_cpus

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


COMMAND_ENV = "ELICIT_JAX_COMMAND"
"""Environment variable holding the command that asked for the work, set where the process
running it is not the one the user started (a Ray worker runs a stage of the driver's
``pipeline run``; without it the worker would record its own launcher's command line)."""


def current_command() -> str:
    """The command line that asked for what this process makes: :data:`COMMAND_ENV` when set,
    else this process's own arguments (the program's file name, then its arguments;
    ``python -c …`` for code given on the command line, which Python does not keep)."""
    given = os.environ.get(COMMAND_ENV)
    if given:
        return given
    if not sys.argv:
        return ""
    # `python -c CODE ARGS` leaves "-c" in argv[0] and drops CODE: say so rather than "-c ARGS"
    program = "python -c …" if sys.argv[0] == "-c" else shlex.quote(Path(sys.argv[0]).name)
    return " ".join([program, *map(shlex.quote, sys.argv[1:])])


SOURCE_DATE_EPOCH = "SOURCE_DATE_EPOCH"
"""The reproducible-builds variable: when set (seconds since 1970), every time an artifact
records is that time, so identical runs give identical bytes (docs/outputs.md)."""


def recorded_now() -> str:
    """The time an artifact records (its ``created`` and ``provenance.time``): now (UTC, to
    the second), or :data:`SOURCE_DATE_EPOCH` when that is set."""
    epoch = os.environ.get(SOURCE_DATE_EPOCH, "").strip()
    when = (
        _dt.datetime.fromtimestamp(int(epoch), _dt.UTC)
        if epoch.isdigit()
        else _dt.datetime.now(_dt.UTC)
    )
    return when.isoformat(timespec="seconds")


def provenance() -> dict[str, Any]:
    """Where an artifact made now comes from: code commit and dirty flag, the command line,
    the elicit-jax and library versions and the UTC time (kept under
    :data:`PROVENANCE_KEY` in every header)."""
    versions = library_versions()
    return {
        **code_commit(),
        "elicit_jax": versions.get("elicit-jax", "unknown"),
        "versions": versions,
        "command": current_command(),
        "python": platform.python_version(),
        "time": recorded_now(),
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
        f"{prov.get('elicit_jax', '?')} ({libs}); command `{shown_command(prov)}`; "
        f"made {prov.get('time', '?')}.{results}"
    )


def shown_command(prov: Mapping[str, Any]) -> str:
    """The recorded command as a report shows it: an absolute path (a folder of the machine
    that ran it, which a reader does not have) is shortened to ``…/`` and its last part; the
    record itself keeps the whole path."""
    words = shlex.split(str(prov.get("command", "?")))
    return " ".join(
        f"…/{shlex.quote(Path(w).name)}" if w.startswith("/") else shlex.quote(w) for w in words
    )


def shown_path(path: str | Path, root: str | Path | None = None) -> str:
    """A path as a report shows it: a relative path unchanged; an absolute one (a folder of
    the machine that made it) relative to the folder named like ``root``'s last part when it
    lies below one, else shortened to ``…/`` and its last part, as :func:`shown_command` does.

    >>> shown_path("/home/me/runs/study/policies/seed0", "runs/study")
    'policies/seed0'
    >>> shown_path("/home/me/runs/study")
    '…/study'
    """
    p = Path(path)
    if not p.is_absolute():
        return str(p)
    name = Path(root).name if root is not None else None
    parts = p.parts
    if name and name in parts[:-1]:
        below = parts[len(parts) - parts[::-1].index(name) :]
        return str(Path(*below))
    return f"…/{p.name}"


def shown_paths_in(text: str, root: str | Path | None = None) -> str:
    """``text`` with every absolute path in it shown by :func:`shown_path`."""
    return re.sub(r"(?<![\w.~])/[^\s,;()`'\"]+", lambda m: shown_path(m.group(0), root), text)


def runtime_settings() -> dict[str, Any]:
    """Settings outside the config that can change numerics: XLA flags, the XLA CPU thread
    count, CPUs and the CPU model (results are bit-identical only for the same CPU model and
    thread count: docs/outputs.md, "Across machines")."""
    return {
        "XLA_FLAGS": os.environ.get("XLA_FLAGS", ""),
        "PJRT_NPROC": os.environ.get("PJRT_NPROC", ""),
        "cpus": available_cpus(),
        "machine": platform.machine(),
        "cpu": cpu_model(),
        "cpu_isa": cpu_isa(),
    }


@functools.cache
def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``; elsewhere what :mod:`platform` says)."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith(("model name", "hardware", "cpu model")):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine() or "unknown"


ISA_LEVELS = ("amx_tile", "avx512f", "avx2", "avx", "sse4_2", "sve", "asimd")
"""Vector instruction sets, widest first: the matmul kernels XLA's CPU backend runs are
chosen from them at run time."""


@functools.cache
def cpu_isa() -> str:
    """The widest of :data:`ISA_LEVELS` the CPU has (``/proc/cpuinfo`` flags), else
    ``unknown``."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith(("flags", "features")):
                have = set(line.split(":", 1)[1].split())
                return next((isa for isa in ISA_LEVELS if isa in have), "unknown")
    return "unknown"
