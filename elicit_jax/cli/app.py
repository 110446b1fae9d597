"""The Typer application, its global options and the entry point's error handling.

Command modules register on :data:`app`; they import JAX, MuJoCo and friends lazily,
inside the commands, so that ``elicit-jax --help`` starts fast.
"""

from __future__ import annotations

import sys

import typer

from elicit_jax.errors import ElicitError

app = typer.Typer(
    name="elicit-jax",
    help=(
        "Measure and elicit demonstrations compatible with a base policy.\n\n"
        "Stages pass Parquet artifacts: import/collect -> train -> score -> fit-thresholds "
        "-> filter -> train -> evaluate. Run any command with --help for an example."
    ),
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)

_state = {"debug": False}


@app.callback()
def _root(
    debug: bool = typer.Option(False, "--debug", help="Show full tracebacks on errors."),
) -> None:
    _state["debug"] = debug


def main() -> None:
    """Console-script entry point: set up JAX, run the app, print errors as one line."""
    from elicit_jax import cli as _commands  # noqa: F401  (registers the commands)
    from elicit_jax.runtime import configure

    configure()
    debug = "--debug" in sys.argv[1:]
    try:
        app()
    except ElicitError as e:
        if debug:
            raise
        typer.echo(f"error: {e}", err=True)
        sys.exit(1)
    except (OSError, ValueError) as e:
        if debug:
            raise
        typer.echo(f"error: {type(e).__name__}: {e}", err=True)
        sys.exit(1)
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        sys.exit(130)
