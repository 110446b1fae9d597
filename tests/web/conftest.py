"""Fixtures of the browser-interface tests: the `serve --demo` inputs, built once per run."""

from __future__ import annotations

import dataclasses
import os

import pytest
from chromium import CHROMIUM_NAMES, FLAGS, find_chromium

from elicit_jax.elicit.config import SessionConfig


@pytest.fixture(scope="session")  # session scope: looked for before the demo inputs are built
def browser():
    chromium = find_chromium()
    if chromium is None:
        where = os.environ.get("ELICIT_JAX_CHROMIUM") or " or ".join(CHROMIUM_NAMES) + " on PATH"
        reason = (
            f"no Chromium found ({where}): install Debian's package (apt-get install chromium) "
            "to run the browser test"
        )
        if os.environ.get("ELICIT_JAX_REQUIRE_BROWSER") == "1":
            pytest.fail(reason + " (ELICIT_JAX_REQUIRE_BROWSER=1)")
        pytest.skip(reason)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=chromium, args=FLAGS)
        yield b
        b.close()


@pytest.fixture(scope="session")
def demo(tmp_path_factory):
    """The built-in reach-pillar inputs of `serve --demo` (the recipe users get), in a
    temporary cache directory: 20 base demos, a 5 x 128-128 policy, fitted thresholds."""
    import io

    from rich.console import Console

    from elicit_jax.pipeline.serve_demo import DemoRecipe, demo_inputs

    root = tmp_path_factory.mktemp("serve-demo")
    quiet = Console(file=io.StringIO())
    return demo_inputs(DemoRecipe(), root, echo=lambda _: None, console=quiet)


@pytest.fixture(scope="session")
def template(demo) -> SessionConfig:
    """A session config over the demo inputs: 1 practice episode, a prompt of 2, 1 demo."""
    from elicit_jax.compat.thresholds import read_thresholds

    thresholds = read_thresholds(demo.thresholds)
    return SessionConfig(
        task="reach-pillar",
        policy=str(demo.policy),
        base_demos=str(demo.base_demos),
        thresholds=thresholds,
        operator="browser:_",
        practice=1,
        prompt=2,
        demos=1,
        max_episodes=6,
    )


def with_settings(template: SessionConfig, **kw) -> SessionConfig:
    return dataclasses.replace(template, **kw)
