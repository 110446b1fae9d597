"""Command-line interface: ``elicit-jax``. Importing this package registers every command."""

from elicit_jax.cli import data_cmds  # noqa: F401
from elicit_jax.cli.app import app, main

__all__ = ["app", "main"]
