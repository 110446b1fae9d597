"""The thresholds flags the commands share: ``--thresholds``, ``--lambda``/``--eta``, ``--preset``.

Declared once so ``score``, ``filter``, ``map``, ``elicit``, ``serve`` and ``watch`` spell and
document them the same way; :func:`thresholds_from_flags` resolves them through
:func:`elicit_jax.compat.threshold_source.resolve_thresholds` and shows the file's verdict.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import typer

from elicit_jax.compat.threshold_source import resolve_thresholds
from elicit_jax.compat.thresholds import Thresholds

THRESHOLDS = typer.Option(None, "--thresholds", help="A thresholds.json from fit-thresholds.")
LAMBDA = typer.Option(None, "--lambda", help="Likelihood-error threshold λ.")
ETA = typer.Option(None, "--eta", help="Novelty threshold η.")
FORCE = typer.Option(
    False,
    "--force",
    help="Apply thresholds fitted for another policy, or the raw-unit stand-ins of "
    "--action-scale std scores, anyway (a warning says so).",
)
PRESET = typer.Option(
    None, "--preset", help="Paper thresholds: square-nut, round-nut or hammer-drawer."
)
FLAGS = (
    ("thresholds", Path | None, THRESHOLDS),
    ("lambda_", float | None, LAMBDA),
    ("eta", float | None, ETA),
)
"""The thresholds flags as (parameter name, type, option): a command adds them with
:func:`elicit_jax.cli.params.with_flags` and resolves them with :func:`from_params`."""
FLAGS_AND_PRESET = (*FLAGS, ("preset", str | None, PRESET))
"""The same with ``--preset`` (``score``, ``elicit``, ``serve``, ``watch``)."""
HAND_SET = (
    (
        "lambda_",
        float | None,
        typer.Option(
            None,
            "--lambda",
            help="Hand-set λ instead of fitting (with --eta); contrast sets, if given, only "
            "evaluate it.",
        ),
    ),
    ("eta", float | None, typer.Option(None, "--eta", help="Hand-set η (with --lambda).")),
)
"""``fit-thresholds``'s hand-set λ and η (:func:`hand_set` resolves them)."""
APPLY_FLAGS = (*FLAGS, ("force", bool, FORCE))
"""The flags of the commands that apply thresholds to a scores file (``filter``, ``map``):
:data:`FLAGS` and ``--force``."""


def from_params(params: Mapping[str, Any], action_scale: str | None = None) -> Thresholds | None:
    """:func:`thresholds_from_flags` of a command's parameters (``ctx.params``).

    Args:
      params: the command's parameters: those of :data:`FLAGS` (and ``preset`` if it has it).
      action_scale: the scale of the scores they apply to (None: no check).

    Returns:
      The thresholds, or None when no flag gives them.
    """
    flags = (params["thresholds"], params["lambda_"], params["eta"], params.get("preset"))
    return thresholds_from_flags(*flags, action_scale=action_scale)


def thresholds_from_flags(
    *flags: Path | float | str | None, action_scale: str | None = None
) -> Thresholds | None:
    """Resolve the thresholds flags; a file's recorded trust verdict goes to stderr.

    Args:
      *flags: ``--thresholds``, ``--lambda``, ``--eta`` and, for the commands that have it,
        ``--preset``, as :func:`~elicit_jax.compat.threshold_source.resolve_thresholds`
        takes them.
      action_scale: the scale of the scores they apply to, to check units (None: no check).

    Returns:
      The thresholds, or None when no flag gives them.
    """
    resolved = resolve_thresholds(*flags, action_scale=action_scale)  # type: ignore[arg-type]
    line = resolved.verdict_line() if resolved is not None else None
    if line is not None:
        typer.echo(line, err=True)
    return resolved


def show_chosen(thresholds: Thresholds) -> None:
    """Say on stderr which (λ, η) a command runs with and where they came from."""
    typer.echo(f"thresholds: {thresholds.describe()}", err=True)


def show_applied(lines: list[str]) -> None:
    """Print the lines :func:`~elicit_jax.compat.threshold_source.applied_thresholds` returns (which
    λ, η a command applies and where they came from; warnings) to stderr."""
    for line in lines:
        typer.echo(line, err=True)


def hand_set(params: Mapping[str, Any]) -> Thresholds | None:
    """The thresholds ``fit-thresholds --lambda --eta`` sets by hand (None without them)."""
    return resolve_thresholds(None, params["lambda_"], params["eta"])
