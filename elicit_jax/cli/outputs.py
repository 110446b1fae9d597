"""The ``--overwrite`` option every command that writes files shares, and the check it drives.

One rule (:func:`elicit_jax.artifact.check_outputs`): an existing directory is never replaced
by an output, an existing file only with ``--overwrite``, and nothing is written over or
inside an input.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import typer

OVERWRITE = typer.Option(
    False, "--overwrite", help="Replace an existing output file (never a directory)."
)


def policy_dirs(specs: Iterable[str]) -> list[Path]:
    """The directories of ``--policy`` values ``DIR`` or ``LABEL=DIR``."""
    return [Path(s.split("=", 1)[1] if "=" in s else s) for s in specs]
