"""Data commands: import, export, info."""

from __future__ import annotations

from pathlib import Path

import typer

from elicit_jax.cli.app import app


@app.command()
def info(
    artifact: Path = typer.Argument(..., help="Any elicit-jax artifact (file or directory)."),
) -> None:
    """Describe an artifact: its kind, schema version, shapes and provenance.

    Example: elicit-jax info demos.parquet
    """
    from elicit_jax.describe import describe

    describe(artifact)
