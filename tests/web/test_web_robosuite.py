"""``serve`` on robosuite-square in real headless Chromium: the page draws robosuite's scene
(built from the environment's own MjModel, primitives only) and, once the operator presses a
key, the streamed poses move the arm and the live indicator lights up.

The server runs in this process (uvicorn on a thread), so it shares the process's robosuite
environment with the fixture that recorded the base demonstration: one environment build
for the module. Skipped without robosuite, except under ELICIT_JAX_REQUIRE_ROBOSUITE=1 (CI);
without Chromium as the other browser tests are.
"""

from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest
from chromium import page_with_errors, sign_in
from fixtures_data import skip_without_robosuite

skip_without_robosuite()

TASK = "robosuite-square"
SHOTS = os.environ.get("ELICIT_JAX_SCREENSHOTS")


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """One base demonstration by the scripted base operator (in this process's robosuite
    environment) and a tiny policy trained on it."""
    from fixtures_data import tiny_train_config

    from elicit_jax.data.demos import from_episodes, read_demos, write_demos
    from elicit_jax.policy.train import train_policy
    from elicit_jax.sim.collect import operator_rng, run_batch
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.operators import make_operator
    from elicit_jax.sim.single import open_env

    d = tmp_path_factory.mktemp("rs-serve")
    task = make_task(TASK)
    with open_env(task) as env:
        seeds = np.array([7])
        out = run_batch(task, make_operator(task, "base"), env, seeds, operator_rng(0, "base"))
    assert out["success"][0]
    n = int(out["length"][0])
    reward = np.zeros(n, np.float32)
    reward[-1] = 1.0
    episode = {"obs": out["obs"][0, :n], "action": out["action"][0, :n], "reward": reward,
               "init_seed": np.full(n, 7, np.int64)}  # fmt: skip
    demos = from_episodes([episode], operators="base", task=TASK, obs_fields=task.obs_fields,
                          action_low=-1.0, action_high=1.0)  # fmt: skip
    write_demos(d / "base.parquet", demos, config={}, seed=0)
    train_policy(read_demos(d / "base.parquet"), tiny_train_config(), d / "run", quiet=True)
    return d


@pytest.fixture
def server(inputs, tmp_path):
    """``serve``'s app for robosuite-square on a free port, in this process."""
    import uvicorn

    from elicit_jax.compat.thresholds import Thresholds
    from elicit_jax.elicit.config import SessionConfig
    from elicit_jax.web.access import access_policy
    from elicit_jax.web.hub import OperatorHub
    from elicit_jax.web.serve import ServeConfig, bind, preflight, url_of
    from elicit_jax.web.server import create_app

    session = SessionConfig(task=TASK, policy=str(inputs / "run"),
                            base_demos=str(inputs / "base.parquet"),
                            thresholds=Thresholds(0.4, 0.05, "given"),
                            operator="browser:_", practice=0, prompt=0, demos=1,
                            max_episodes=2, horizon=80)  # fmt: skip
    config = ServeConfig(session=session, sessions=str(tmp_path / "sessions"), port=0)
    preflight(config.session)  # what `serve` checks before it binds
    hub = OperatorHub(session, tmp_path / "sessions", log=lambda _: None)
    sock = bind("127.0.0.1", 0)
    port = sock.getsockname()[1]
    app = create_app(hub, access_policy("127.0.0.1", port, None, admin_token="admin-for-tests"))
    srv = uvicorn.Server(uvicorn.Config(app, log_level="warning", lifespan="on"))
    thread = threading.Thread(target=srv.run, kwargs={"sockets": [sock]}, daemon=True)
    thread.start()
    while not srv.started:
        time.sleep(0.05)
    yield url_of("127.0.0.1", port, None)
    srv.should_exit = True
    thread.join(10)
    hub.shutdown()
    sock.close()


def test_robosuite_scene_and_indicator_in_chromium(browser, server):
    page, errors = page_with_errors(browser, {"width": 1000, "height": 640})
    try:
        sign_in(page, server, "rob")
        page.wait_for_selector("body[data-screen=demonstrate][data-state=ready]",
                               state="attached", timeout=120_000)  # fmt: skip
        desc = page.evaluate(
            "() => ({n: elicit.view.desc.items.length, bodies: elicit.view.desc.bodies,"
            " meshes: elicit.view.instances[0].scene.getObjectByName('robot0_link4_collision')"
            " !== undefined, gripper: elicit.view.desc.gripper})"
        )
        assert desc["n"] > 40 and "SquareNut_main" in desc["bodies"] and desc["meshes"]
        eef = desc["gripper"]
        before = page.evaluate("(b) => elicit.bodyPosition(b)", eef)
        assert abs(before[2]) < 0.4  # the gripper starts just above the table top (height 0)
        page.keyboard.down("KeyR")  # up: a real key press starts the episode
        page.wait_for_function(
            "() => ['green', 'red', 'unfamiliar']"  # a lit state (no data there: its own)
            ".includes(document.getElementById('indicator').dataset.state)",
            timeout=60_000,
        )
        page.wait_for_function(
            "([b, z]) => elicit.bodyPosition(b)[2] > z + 0.02", arg=[eef, before[2]],
            timeout=60_000,
        )  # fmt: skip
        page.keyboard.up("KeyR")
        if SHOTS:
            page.evaluate("() => elicit.view.setFullQuality(true)")
            page.screenshot(path=os.path.join(SHOTS, "serve-robosuite.png"))
        assert not errors, errors
    finally:
        page.close()
