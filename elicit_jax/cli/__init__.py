"""Command-line interface: ``elicit-jax``. Importing this package registers every command."""

from elicit_jax.cli import (
    compat_cmds,  # noqa: F401
    curation_cmds,  # noqa: F401
    data_cmds,  # noqa: F401
    demos_cmds,  # noqa: F401
    elicit_cmds,  # noqa: F401
    pipeline_cmds,  # noqa: F401
    score_cmd,  # noqa: F401
    serve_cmd,  # noqa: F401
    sim_cmds,  # noqa: F401
    train_cmd,  # noqa: F401
)
from elicit_jax.cli.app import app, main

__all__ = ["app", "main"]
