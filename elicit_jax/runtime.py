"""Process-level set-up, applied at the CLI entry point and in the test configuration.

Nothing here runs at import time: callers invoke :func:`configure` before importing JAX, and
the CLI calls :func:`configure_logging` to decide where the library's log records go and
:func:`configure_console` to keep Rich's tables whole in a file or a pipe.
"""

from __future__ import annotations

import logging
import logging.handlers
import os
import sys
from pathlib import Path

MJX_CPU_XLA_FLAGS = "--xla_cpu_use_fusion_emitters=false"
CACHE_ENV = "ELICIT_JAX_CACHE_DIR"
MJX_MIN_THREADS = 4
LOG_ENV = "ELICIT_JAX_LOG"
THREADS_OWNER_ENV = "ELICIT_JAX_PJRT_NPROC_DEFAULT"
"""Set (to ``1``) when :func:`configure` chose ``PJRT_NPROC``, so that a child process (a Ray
worker inherits its driver's environment) may size it anew for its own CPUs; a user's
``PJRT_NPROC`` never carries it and is left alone."""


WIDE_CONSOLE = 200
WIDE_OWNER_ENV = "ELICIT_JAX_WIDE_COLUMNS"
"""Set (to ``1``) when :func:`configure_console` chose ``COLUMNS``."""


def configure_console() -> None:
    """Widen Rich's consoles when stdout is not a terminal (a file, a pipe).

    Rich sizes a console from the terminal on stdin/stdout/stderr, else 80 columns, and
    squeezes a table into that width, cutting its cells (``axis_operat…``) in a file where
    nothing limits the width. With stdout redirected and no ``COLUMNS`` set by the user,
    ``COLUMNS`` is set to :data:`WIDE_CONSOLE`; a console on a terminal stderr (progress
    bars) takes :func:`stderr_width` instead.
    """
    if "COLUMNS" not in os.environ and not _is_terminal(sys.stdout):
        os.environ["COLUMNS"] = str(WIDE_CONSOLE)
        os.environ[WIDE_OWNER_ENV] = "1"


def stderr_width() -> int | None:
    """The width a console on stderr should take: the terminal's when stderr is one and
    :func:`configure_console` widened ``COLUMNS`` for stdout, else ``None`` (Rich decides)."""
    if os.environ.get(WIDE_OWNER_ENV) != "1" or not _is_terminal(sys.stderr):
        return None
    try:
        return os.get_terminal_size(sys.stderr.fileno()).columns
    except (OSError, ValueError, AttributeError):
        return None


def _is_terminal(stream: object) -> bool:
    try:
        return bool(stream.isatty())  # type: ignore[attr-defined]
    except (AttributeError, ValueError):
        return False


def default_cache_dir() -> Path:
    """Directory of JAX's persistent compilation cache (``$ELICIT_JAX_CACHE_DIR`` wins)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "elicit-jax" / "jax"


def configure(cache_dir: Path | None = None, *, mjx: bool = False, cpus: int | None = None) -> None:
    """Set XLA flags, XLA's CPU thread count and JAX's compilation cache via the environment.

    Must run before JAX is imported. User-set ``XLA_FLAGS``, ``PJRT_NPROC`` and
    ``JAX_COMPILATION_CACHE_DIR`` are left untouched. Without the fusion-emitter flag,
    MJX on CPU slows down exponentially with kinematic-chain depth (jax 0.10).
    ``PJRT_NPROC`` (XLA's CPU thread pool) is :func:`cpu_threads`: one thread per CPU, so
    the matmuls of scoring, training and policy calls do not oversubscribe the cores; with
    ``mjx`` at least :data:`MJX_MIN_THREADS`, which MJX needs (:func:`check_mjx_threads`).

    Args:
      cache_dir: cache location; defaults to :func:`default_cache_dir`.
      mjx: this process will step MJX on the CPU.
      cpus: the CPUs this process's work may use, when fewer than it can run on (a Ray task
        holding one CPU of two); a ``PJRT_NPROC`` inherited from a parent's
        :func:`configure` is sized anew for them.
    """
    os.environ.setdefault("XLA_FLAGS", MJX_CPU_XLA_FLAGS)
    ours = os.environ.get(THREADS_OWNER_ENV) == "1"
    if "PJRT_NPROC" not in os.environ or (ours and cpus is not None):
        os.environ["PJRT_NPROC"] = str(cpu_threads(mjx, cpus))
        os.environ[THREADS_OWNER_ENV] = "1"
    if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
        path = cache_dir or default_cache_dir()
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError:
            return
        os.environ["JAX_COMPILATION_CACHE_DIR"] = str(path)
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES", "0")


def cpu_threads(mjx: bool = False, cpus: int | None = None) -> int:
    """XLA CPU threads for a process: one per CPU (``cpus``, default all it may run on); at
    least :data:`MJX_MIN_THREADS` with MJX."""
    cpus = max(1, int(cpus)) if cpus is not None else available_cpus()
    return max(MJX_MIN_THREADS, cpus) if mjx else cpus


def check_mjx_threads() -> None:
    """Refuse to step MJX on a CPU thread pool too small for it.

    jaxlib 0.10's batched LAPACK kernels (MJX's Cholesky solves) split large batches onto
    XLA's CPU thread pool and block waiting for them, so on a 2-core machine two concurrent
    solves deadlock a 2-thread pool (MJX with 1000 environments hung at 0% CPU). The pool
    must have :data:`MJX_MIN_THREADS` threads; it is sized when JAX starts, from
    ``PJRT_NPROC`` (default: the CPU count). No check on other platforms.

    Raises:
      ElicitError: JAX runs on the CPU with a smaller pool.
    """
    import jax

    from elicit_jax.errors import ElicitError

    if jax.default_backend() != "cpu":
        return
    threads = int(os.environ.get("PJRT_NPROC") or available_cpus())
    if threads < MJX_MIN_THREADS:
        raise ElicitError(
            f"MJX on the CPU needs XLA's CPU thread pool to have at least {MJX_MIN_THREADS} "
            f"threads (jaxlib's batched LAPACK deadlocks a smaller one); this process has "
            f"{threads}: set PJRT_NPROC={MJX_MIN_THREADS} before starting it, or use the C "
            "MuJoCo backend (--backend mujoco)"
        )


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


def default_log_path() -> Path:
    """The CLI's log file: ``$ELICIT_JAX_LOG``, else ``elicit-jax/elicit-jax.log`` in the
    user's state directory (``$XDG_STATE_HOME`` or ``~/.local/state``)."""
    if os.environ.get(LOG_ENV):
        return Path(os.environ[LOG_ENV]).expanduser()
    base = os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state"
    return Path(base) / "elicit-jax" / "elicit-jax.log"


def configure_logging(path: Path | None = None, echo: bool = False) -> Path | None:
    """Send the ``elicit_jax`` loggers' records (INFO and above) to a log file.

    The file rotates at 1 MB (two old files kept). Records never reach the terminal unless
    ``echo`` (the CLI's ``--debug``), which also prints them on stderr. Calling it again
    replaces the handlers it added before.

    Args:
      path: log file; defaults to :func:`default_log_path`.
      echo: also print every record on stderr.

    Returns:
      The log file, or None when it cannot be created (then records are dropped, or only
      echoed).
    """
    logger = logging.getLogger("elicit_jax")
    for old in [h for h in logger.handlers if getattr(h, "elicit_jax_cli", False)]:
        logger.removeHandler(old)  # called again (e.g. in-process CLI runs): replace, not add
        old.close()
    logger.setLevel(logging.INFO)
    logger.propagate = False
    fmt = logging.Formatter("%(asctime)s %(process)d %(name)s %(levelname)s %(message)s")
    path = path or default_log_path()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handler: logging.Handler = logging.handlers.RotatingFileHandler(
            path, maxBytes=1_000_000, backupCount=2, encoding="utf-8"
        )
    except OSError:
        handler, path = logging.NullHandler(), None
    handlers = [handler, logging.StreamHandler()] if echo else [handler]
    for h in handlers:
        h.setFormatter(fmt)
        h.elicit_jax_cli = True  # type: ignore[attr-defined]
        logger.addHandler(h)
    return path
