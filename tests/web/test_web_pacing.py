"""The end of an episode stays off the frames: its last state is shown before it is judged.

A session stepped with ``finish=False`` leaves an ended episode open until
``finish_episode()`` and then writes exactly what ``step()`` would have written; the driver
uses that to send an episode's last pose frame before the episode is judged and written (the
judging and the Parquet write take milliseconds that the frame must not wait for).
"""

from __future__ import annotations

import dataclasses
import json
import threading
import time

import numpy as np
import pytest

from elicit_jax.elicit.run import run_session
from elicit_jax.elicit.session import Session
from elicit_jax.elicit.setup import open_session
from elicit_jax.errors import ElicitError
from elicit_jax.web.driver import OperatorDriver
from elicit_jax.web.protocol import Message, unpack
from elicit_jax.web.scene import body_poses

SAME = ("obs", "action", "qpos", "qvel", "operator", "likelihood", "novelty", "compatibility")


def test_a_deferred_finish_writes_what_step_writes(template, tmp_path):
    config = dataclasses.replace(
        template, operator="scripted:base", practice=0, prompt=0, demos=1, max_episodes=1
    )
    setup, operator, _ = open_session(config, tmp_path / "now")
    run_session(setup, operator)
    now = setup.store.read_episode(0)

    setup, operator, _ = open_session(config, tmp_path / "later")
    session = Session(setup, [operator.on_event])
    session.start()
    while not session.episode_over:
        session.step(operator.act(session.observation()), finish=False)
    assert setup.store.episode_files() == []  # ended, not yet judged or written
    with pytest.raises(ElicitError, match="finish_episode"):
        session.observation()
    last = body_poses(session.sim_data)  # the last state, still there to draw
    session.finish_episode()
    assert session.done and len(setup.store.episode_files()) == 1
    later = setup.store.read_episode(0)

    assert (later.verdict, later.length, later.success) == (now.verdict, now.length, now.success)
    assert later.feedback == now.feedback and later.text == now.text
    for name in SAME:
        np.testing.assert_array_equal(getattr(later, name), getattr(now, name), err_msg=name)
    assert np.isfinite(last).all() and last.shape[1] == 7


class Recorder:
    """An outbox that notes, for each message, whether the episode file was on disk yet."""

    def __init__(self, episode_file) -> None:
        self.episode_file = episode_file
        self.sent: list[tuple[dict, bool]] = []
        self.ended = threading.Event()

    def send(self, message, droppable: bool = False) -> None:
        written = self.episode_file.exists()
        if isinstance(message, bytes):
            msg = unpack(message)
            if msg["kind"] == "frame":
                self.sent.append(({"type": "frame", **msg}, written))
            return
        msg = json.loads(message)
        self.sent.append((msg, written))
        if _is_end(msg):
            self.ended.set()


def test_the_last_frame_is_sent_before_the_episode_is_judged_and_written(template, tmp_path):
    config = dataclasses.replace(
        template, practice=0, prompt=0, demos=1, max_episodes=2, horizon=5, operator="browser:x"
    )
    out = tmp_path / "x"
    outbox = Recorder(out / "episodes" / "e000000.parquet")
    driver = OperatorDriver("x", config, out, log=lambda _: None)
    driver.start()
    try:
        driver.attach(outbox)
        deadline = time.monotonic() + 120
        while driver.state in ("opening",) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert driver.state == "ready", (driver.state, driver.message)
        driver.handle(Message("action", action=(1.0, 0, 0, 0, 0, 0, -1.0)))
        driver.handle(Message("start"))
        assert outbox.ended.wait(120), "the episode did not end"
    finally:
        driver.stop()
    sent = outbox.sent
    end = next(i for i, (m, _) in enumerate(sent) if _is_end(m))
    frames = [(i, m) for i, (m, _) in enumerate(sent[:end]) if _is_frame(m, 0)]
    assert [m["step"] for _, m in frames] == [0, 1, 2, 3, 4, 5]  # the last one: step 5
    last_index, last = frames[-1]
    assert not sent[last_index][1]  # sent while the episode file did not exist yet
    assert sent[end][1]  # the episode-end event: after it was written
    assert sent[end][0]["event"]["length"] == last["step"] == 5
    assert not any(_is_frame(m, 0) for m, _ in sent[end:])  # not sent twice


def _is_end(m: dict) -> bool:
    return m["type"] == "event" and m["event"]["kind"] == "episode-end"


def _is_frame(m: dict, episode: int) -> bool:
    return m["type"] == "frame" and m["episode"] == episode


def test_a_new_command_pulls_the_next_step_forward_by_at_most_half_a_period(template, tmp_path):
    from elicit_jax.web.driver import EARLIEST

    driver = OperatorDriver("x", template, tmp_path / "x", log=lambda _: None)
    driver.period = 1.0  # long against any scheduling delay of a loaded machine
    t = time.perf_counter()
    assert driver._wait_until(t + 0.05) == t + 0.05  # no command: on the grid
    driver.handle(Message("start"))  # not a command: no early step
    driver.operator = type("Op", (), {"set_action": lambda self, a: None})()
    driver.handle(Message("action", action=(1.0, 0, 0, 0, 0, 0, -1.0)))
    due = time.perf_counter() + driver.period
    assert driver._wait_until(due) == due - EARLIEST * driver.period  # half a period early
    driver._command.clear()
    driver.handle(Message("action", action=(1.0, 0, 0, 0, 0, 0, -1.0)))  # the same: no news
    due = time.perf_counter() + 0.2
    assert driver._wait_until(due) == due
    driver.stop()
    assert driver._wait_until(time.perf_counter() + 5) is None


def test_changing_commands_never_run_an_episode_faster_than_the_control_rate(template, tmp_path):
    """A command changing at every step (a gamepad's stick) pulls steps forward, but the
    steps stay on their grid: the episode keeps the control rate."""
    config = dataclasses.replace(
        template, practice=0, prompt=0, demos=1, max_episodes=2, horizon=40, operator="browser:x"
    )
    out = tmp_path / "x"
    driver = OperatorDriver("x", config, out, log=lambda _: None)
    driver.start()
    try:
        deadline = time.monotonic() + 120
        while driver.state == "opening" and time.monotonic() < deadline:
            time.sleep(0.05)
        assert driver.state == "ready", (driver.state, driver.message)
        driver.handle(Message("action", action=(0.5, 0, 0, 0, 0, 0, -1.0)))
        driver.handle(Message("start"))
        t0, i = time.perf_counter(), 0
        while driver.steps < 30 and time.perf_counter() - t0 < 60:
            i += 1
            driver.handle(Message("action", action=(0.5 + 0.01 * (i % 2), 0, 0, 0, 0, 0, -1.0)))
            time.sleep(0.01)  # a changed command every 10 ms
        elapsed = time.perf_counter() - t0
    finally:
        driver.stop()
    assert driver.steps >= 30
    # 30 steps at 20 Hz take 29 periods at least, less the first step's half period early
    assert elapsed >= (29 - EARLIEST_SLACK) * driver.period, elapsed


EARLIEST_SLACK = 0.5
