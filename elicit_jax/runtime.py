"""Process-level JAX set-up, applied at the CLI entry point and in the test configuration.

Nothing here runs at import time; callers invoke :func:`configure` before importing JAX.
"""

from __future__ import annotations

import os
from pathlib import Path

MJX_CPU_XLA_FLAGS = "--xla_cpu_use_fusion_emitters=false"
CACHE_ENV = "ELICIT_JAX_CACHE_DIR"
MIN_CPU_THREADS = 4


def default_cache_dir() -> Path:
    """Directory of JAX's persistent compilation cache (``$ELICIT_JAX_CACHE_DIR`` wins)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "elicit-jax" / "jax"


def configure(cache_dir: Path | None = None) -> None:
    """Set XLA flags and JAX's persistent compilation cache through the environment.

    Must run before JAX is imported. User-set ``XLA_FLAGS``, ``PJRT_NPROC`` and
    ``JAX_COMPILATION_CACHE_DIR`` are left untouched. Without the fusion-emitter flag,
    MJX on CPU slows down exponentially with kinematic-chain depth (jax 0.10). ``PJRT_NPROC``
    gives XLA's CPU thread pool at least four threads: jaxlib 0.10's batched LAPACK kernels
    (MJX's Cholesky solves) split large batches onto that pool and block waiting for them,
    so on a 2-core machine two concurrent solves deadlock it (MJX with 1000 environments
    hung at 0% CPU).

    Args:
      cache_dir: cache location; defaults to :func:`default_cache_dir`.
    """
    os.environ.setdefault("XLA_FLAGS", MJX_CPU_XLA_FLAGS)
    os.environ.setdefault("PJRT_NPROC", str(max(MIN_CPU_THREADS, available_cpus())))
    if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
        path = cache_dir or default_cache_dir()
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError:
            return
        os.environ["JAX_COMPILATION_CACHE_DIR"] = str(path)
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES", "0")


def available_cpus() -> int:
    """The CPUs this process may run on (its affinity mask, else the machine's count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


def process_alive(pid: int) -> bool:
    """True when a process with this id exists on this machine (or may: no permission)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OverflowError:
        return False
    return True
