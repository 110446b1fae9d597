"""The live state (elicit/light.py): it never contradicts the episode's final verdict."""

from __future__ import annotations

import numpy as np
import pytest

from elicit_jax.elicit.light import is_idle, live_state, rule_words
from elicit_jax.elicit.rules import AcceptRule
from elicit_jax.sim.env import ACTION_NAMES


def _states(rule, horizon, reds):
    out, red = [], 0
    for t, r in enumerate(reds, 1):
        red += int(r)
        out.append(
            live_state(rule, horizon, red, t, incompatible=bool(r), unfamiliar=False, idle=False)
        )
    return out


@pytest.mark.parametrize("rule", [AcceptRule(), AcceptRule(fraction=0.1), AcceptRule(count=3)])
def test_the_live_state_never_contradicts_the_final_verdict(rule):
    rng = np.random.default_rng(0)
    horizon = 180
    for _ in range(300):
        length = int(rng.integers(1, horizon + 1))
        reds = rng.random(length) < rng.uniform(0.0, 0.15)
        states = _states(rule, horizon, reds)
        final_reject = rule.rejects(int(reds.sum()), length)
        assert states[-1].accept_now == (not final_reject)  # the verdict if it ended now
        for s in states:
            assert s.allowed == states[0].allowed  # fixed by the horizon, never growing
            if s.doomed:  # "can no longer be accepted" is never wrong
                assert final_reject and not s.accept_now
            assert s.left == max(0, s.allowed - s.red)
        # and it is said the moment the red steps exceed the allowance
        first = next((i for i, s in enumerate(states) if s.red > s.allowed), None)
        assert [s.doomed for s in states] == [
            first is not None and i >= first for i in range(length)
        ]


def test_the_allowance_is_the_horizons_in_whole_steps():
    s = live_state(AcceptRule(), 180, 9, 40, incompatible=True, unfamiliar=False, idle=False)
    assert (s.allowed, s.left, s.doomed, s.allowed_now, s.accept_now) == (9, 0, False, 2, False)
    s = live_state(AcceptRule(), 180, 10, 41, incompatible=True, unfamiliar=False, idle=False)
    assert s.doomed and s.left == 0
    assert live_state(AcceptRule(count=4), 180, 4, 5, incompatible=False, unfamiliar=False,
                      idle=False).allowed == 4  # fmt: skip


@pytest.mark.parametrize(
    ("incompatible", "unfamiliar", "idle", "light"),
    [
        (True, False, True, "red"),  # the rule counts it: red whatever else
        (False, True, True, "idle"),
        (False, True, False, "unfamiliar"),  # M = 1 by the method's rule, not a fit
        (False, False, True, "idle"),
        (False, False, False, "fits"),
    ],
)
def test_the_light_of_a_step(incompatible, unfamiliar, idle, light):
    s = live_state(AcceptRule(), 100, 0, 1, incompatible=incompatible, unfamiliar=unfamiliar,
                   idle=idle)  # fmt: skip
    assert s.light == light


def test_idle_is_no_motion_and_the_gripper_unchanged():
    still = np.array([0, 0, 0, 0, 0, 0, -1.0])
    assert is_idle(still, None, ACTION_NAMES)
    assert is_idle(still, still, ACTION_NAMES)
    assert not is_idle(np.array([0, -1.0, 0, 0, 0, 0, -1]), still, ACTION_NAMES)  # one axis
    assert not is_idle(np.array([0, 0, 0, 0, 0, 0.3, -1]), still, ACTION_NAMES)  # turning
    assert not is_idle(np.array([0, 0, 0, 0, 0, 0, 1.0]), still, ACTION_NAMES)  # closing


def test_the_rule_in_plain_words():
    words = rule_words(AcceptRule(), 180)
    assert "at most 5% of its steps are red: at most 9 red steps in a full 180-step" in words
    assert "fewer if you finish sooner" in words and "incompatible" not in words
    assert "at most 3 red steps, however long" in rule_words(AcceptRule(count=3), 180)
