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


def note_duplicates(dups: dict[int, int]) -> None:
    """Say which episodes of ``--demos`` were dropped as copies of ``--base`` ones (stderr)."""
    if dups:
        pairs = ", ".join(f"{e} (= base {b})" for e, b in list(dups.items())[:5])
        more = f" and {len(dups) - 5} more" if len(dups) > 5 else ""
        typer.echo(
            f"note: dropped {len(dups)} episode(s) of --demos identical to --base episodes: "
            f"{pairs}{more} (the drop log and the output header list them)",
            err=True,
        )


def drop_reason(reason: str, dups: dict[int, int]) -> str:
    """The filter's reason for the summary line, with the duplicates of ``--base`` counted
    apart (they are dropped whatever the method says)."""
    if not dups:
        return reason
    return f"{len(dups)} episode(s) as duplicates of --base; the others: {reason}"
