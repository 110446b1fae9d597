"""Test configuration: XLA flags and the compilation cache must be set before JAX loads.

The tests step MJX, so XLA's CPU pool gets the threads MJX needs (``mjx=True``).
"""

import os
import tempfile
from pathlib import Path

import pytest

from elicit_jax.runtime import LOG_ENV, configure

configure(mjx=True)
# In-process CLI runs log to a scratch file, not to the user's state directory.
os.environ.setdefault(LOG_ENV, str(Path(tempfile.gettempdir()) / "elicit-jax-tests.log"))


@pytest.fixture
def cli(monkeypatch, capsys):
    """``cli(*args)`` runs ``elicit-jax ARGS`` in-process: (exit code, out, err)
    (:func:`fixtures_data.run_cli`)."""
    from fixtures_data import run_cli

    return lambda *args: run_cli(monkeypatch, capsys, *args)


@pytest.fixture(scope="session")
def square_nut_session_inputs(tmp_path_factory):
    """Square-nut D_base, a tiny base policy and fitted (λ, η), built once for every session
    test module (:func:`fixtures_data.square_nut_session_inputs`); tests only read them."""
    from fixtures_data import square_nut_session_inputs

    return square_nut_session_inputs(tmp_path_factory.mktemp("square-nut-session"))
