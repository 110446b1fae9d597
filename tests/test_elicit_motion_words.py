"""Feedback about motion in the task's own terms, from recorded reach-pillar episodes.

Each episode is recorded by stepping the task's simulator with key-like actions (a held key
is ±1, Shift 0.3, no key 0), so the states are what an operator's episode file holds. Every
motion sentence is checked on an episode where it is true and on one where it is false —
among them the case of issue #49: the gripper moving right at full speed (8 mm a step, one
axis) read as "you hold still where the base moves".
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from elicit_jax.data.demos import from_episodes
from elicit_jax.elicit.explain import explain_episode
from elicit_jax.elicit.plain import gripper_motion, motion_sentences, plain_words
from elicit_jax.sim.env import OBS_FIELDS

STEPS = 14
KEYS = {  # a window of held keys, as the page sends them (the gripper held open: -1)
    "pause": (0, 0, 0),
    "forward": (1, 0, 0),
    "forward-slow": (0.3, 0, 0),
    "right": (0, -1, 0),
    "down": (0, 0, -1),
}


@functools.cache
def record(keys: str, seed: int = 3, before: str = "forward") -> np.ndarray:
    """(STEPS, 23) states of reach-pillar while ``keys`` are held, after 6 steps of
    ``before`` (so a pause starts from motion, as a real one does)."""
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.single import open_env

    obs = []
    with open_env(make_task("reach-pillar")) as sim:
        sim.reset_seeds(np.array([seed]))
        for t in range(6 + STEPS):
            a = np.zeros(7)
            a[:3] = KEYS[before if t < 6 else keys]
            a[6] = -1.0
            obs.append(sim.obs[0].astype(np.float64).copy())
            sim.step(a[None])
    return np.array(obs[6:])


def said(op: str, base: str) -> str:
    return "; ".join(motion_sentences(record(op), record(base, seed=5)))


def test_the_recorded_speeds_are_the_keys():
    assert gripper_motion(record("forward")).speed > 0.007  # ~8 mm a step at full speed
    assert 0.002 < gripper_motion(record("forward-slow")).speed < 0.003
    assert gripper_motion(record("pause")).still and not gripper_motion(record("right")).still


@pytest.mark.parametrize(
    ("sentence", "true", "false"),
    [
        # issue #49: moving right at full speed is not holding still
        ("you hold still where the base moves", ("pause", "forward"), ("right", "forward")),
        ("you move where the base holds still", ("forward", "pause"), ("forward", "forward")),
        (
            "you move right (D) where the base moves forward (W)",
            ("right", "forward"),
            ("forward", "forward"),
        ),
        (
            "you move down (F) where the base moves forward (W)",
            ("down", "forward"),
            ("forward", "forward"),
        ),
        ("× as fast as the base here", ("forward", "forward-slow"), ("forward", "forward")),
        ("% of the base's speed here", ("forward-slow", "forward"), ("forward", "forward")),
    ],
)
def test_each_motion_sentence_is_said_when_true_and_only_then(sentence, true, false):
    assert sentence in said(*true), said(*true)
    assert sentence not in said(*false), said(*false)


def test_the_numbers_in_the_sentences_are_the_recorded_ones():
    line = said("pause", "forward")
    mm = 1000 * gripper_motion(record("forward", seed=5)).speed
    assert "your gripper still in" in line and f"the base's moves {mm:.0f} mm a step" in line
    assert "about 3× as fast" in said("forward", "forward-slow")


def test_a_rejected_window_moving_fast_along_one_axis_is_not_called_still():
    # the operator's episode: forward, then right at full speed (flagged), then forward
    op = np.concatenate([record("forward"), record("right"), record("forward", seed=4)])
    base = from_episodes(
        [{"obs": record("forward", seed=s), "action": np.zeros((STEPS, 7))} for s in (5, 6)],
        obs_fields=OBS_FIELDS,
        task="reach-pillar",
    )
    m = np.ones(len(op))
    m[STEPS : 2 * STEPS] = 0.0
    (fb,) = explain_episode(m, op, np.zeros((len(op), 7)), base, window=STEPS, k=1)
    assert (fb.start, fb.stop) == (STEPS, 2 * STEPS)
    assert fb.motion == "" and "hold still" not in fb.text, fb.text
    assert fb.operator_motion > 0.007  # m a step: the gripper's own speed
    assert "you move right (D) where the base moves forward (W)" in fb.plain, fb.plain
    # the same window paused: now it is true
    op[STEPS : 2 * STEPS] = record("pause")
    (fb,) = explain_episode(m, op, np.zeros((len(op), 7)), base, window=STEPS, k=1)
    assert fb.motion == "still" and "you hold still where the base moves" in fb.text


def test_a_single_step_window_says_nothing_about_motion():
    assert motion_sentences(record("pause")[:1], record("forward")) == []


def test_other_layouts_keep_the_generic_motion_sentence():
    base = record("forward")
    words = plain_words("own-task", [], base, base, base, base, motion="still")
    assert words == ("you hold still where the base moves",)
