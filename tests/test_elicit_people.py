"""Simulated people: they learn only from what the interface shows.

Units: the person spec, populations, the repertoire (never the base style), and feedback that
moves exactly the choice it points at (a synthetic demonstrator who differs from the person in
one choice). Sessions on square-nut (a tiny base policy, thresholds fitted on same-style vs
conflict-flip-pause demos): an informed person runs identically with the base operator's style
made unreadable, changes nothing before feedback points at something, nothing when the
feedback is not shown, nothing in naive mode, and resumes as if never interrupted.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest
from fixtures_data import SessionInputs

from elicit_jax.elicit.config import SessionConfig
from elicit_jax.elicit.events import (
    EpisodeEndEvent,
    EpisodeStartEvent,
    ReviewEvent,
    WindowFeedback,
)
from elicit_jax.elicit.people import SimulatedPerson, make_population, parse_person, person_of
from elicit_jax.elicit.people.imagine import UNSET, calm, imagine, repertoire, with_choice
from elicit_jax.elicit.people.traits import PersonTraits
from elicit_jax.elicit.run import run_session
from elicit_jax.elicit.setup import open_session
from elicit_jax.elicit.store import SessionStore
from elicit_jax.errors import ElicitError

PERSON = "person:conflict-flip-pause,imitation=0,uptake=1,explore=0,noise=2,practice=0.3,seed=5"


class Poisoned:
    """Stands in for the base operator's registry entry: any use of it fails the test."""

    def _fail(self, *_args, **_kw):
        raise AssertionError("the base operator's style was read")

    __iter__ = __getitem__ = __len__ = __getattr__ = _fail


def test_person_spec_round_trip_and_errors():
    p = parse_person("mild,imitation=0.25,uptake=1,seed=4")
    assert (p.style, p.imitation, p.uptake, p.seed, p.explore) == ("mild", 0.25, 1.0, 4, 0.3)
    assert parse_person(p.spec().partition(":")[2]) == p
    for bad, words in [
        ("mild,color=3", "trait=value"),
        ("mild,uptake=1.5", "uptake must be in [0, 1]"),
        ("mild,noise=0.5", "noise must be >= 1"),
        ("mild,seed=x", "seed needs a number"),
        ("mild,explore=nan", "explore must be finite"),
    ]:
        with pytest.raises(ElicitError, match=words.replace("[", r"\[").replace("]", r"\]")):
            parse_person(bad)
    assert p.noise_multiplier(0) == pytest.approx(2.0)
    assert p.noise_multiplier(1) == pytest.approx(1 + 1.0 * 0.75)


def test_population_is_seeded_with_spread():
    a = make_population(["same-style", "conflict-flip-pause"], 6, seed=3)
    assert a == make_population(["same-style", "conflict-flip-pause"], 6, seed=3)
    assert a != make_population(["same-style", "conflict-flip-pause"], 6, seed=4)
    assert [p.style for p in a] == ["same-style", "conflict-flip-pause"] * 3
    assert len({p.seed for p in a}) == 6
    for trait in ("imitation", "uptake", "explore", "noise", "practice"):
        values = [getattr(p, trait) for p in a]
        assert len(set(values)) == 6 and min(values) >= 0
    narrow = make_population(["mild"], 4, seed=0, ranges={"uptake": (0.5, 0.5)})
    assert {p.uptake for p in narrow} == {0.5}
    with pytest.raises(ElicitError, match="unknown trait range"):
        make_population(["mild"], 2, seed=0, ranges={"speed": (0, 1)})


def test_repertoire_is_read_without_the_base_style(monkeypatch):
    mod = importlib.import_module("elicit_jax.sim.operators.square_nut")
    monkeypatch.setitem(mod.STYLES, "base", Poisoned())
    known = repertoire("square-nut")
    assert known["yaw_offset"][0] == UNSET and len(known["yaw_offset"]) >= 2
    with pytest.raises(ElicitError, match="base operator"):
        repertoire("square-nut", ["mild", "base"])
    from elicit_jax.sim.env import make_task

    with pytest.raises(ElicitError, match="cannot start from the base"):
        SimulatedPerson(make_task("square-nut"), PersonTraits("base"), None)


@pytest.fixture(scope="module")
def states():
    """States of two episodes another operator visited (same-style: not the base operator)."""
    from elicit_jax.sim.collect import CollectConfig, collect_episodes

    r = collect_episodes(
        CollectConfig(task="square-nut", operator="same-style", episodes=2, seed=11, batch=2)
    )
    return [ep["obs"].astype(np.float64) for ep in r.episodes]


def _demonstrator(task, person, states, key, value):
    """Base demos whose actions are what the person would do with ``key`` set to ``value``."""
    from elicit_jax.data.demos import from_episodes

    choices = with_choice(person.choices, key, value)
    actions = imagine(task, calm(person.motor, choices), states)
    return from_episodes(
        [{"obs": s, "action": a} for s, a in zip(states, actions, strict=True)],
        obs_fields=task.obs_fields,
    )


def _start(episode, obs=None):
    obs = np.zeros(23) if obs is None else obs
    return EpisodeStartEvent(episode, "demonstration", obs, 1, episode, 500, False, False)


def _review(person, episode, windows):
    person.on_event(_start(episode))
    person.on_event(EpisodeEndEvent(episode, "demonstration", True, 100, 100, False, None))
    person.on_event(ReviewEvent(episode, "rejected", 50, 100, 0.5, "rule", windows, "text"))
    before = dict(person.choices)
    person.on_event(_start(episode + 1))
    return before


def _window(start, stop, base_episode=0):
    return WindowFeedback(start, stop, 1.0, base_episode, start, stop, 0.1, (), (), 0, 0, "", "")


def test_feedback_moves_exactly_the_choice_it_points_at(states):
    from elicit_jax.sim.env import make_task

    task = make_task("square-nut")
    traits = PersonTraits("conflict-flip-pause", imitation=0.0, uptake=1.0, explore=0.0)
    probe = SimulatedPerson(task, traits, None)
    base = _demonstrator(task, probe, states, "pause_at", UNSET)
    # where the demonstrator differs: the first steps (it moves while the person pauses)
    person = SimulatedPerson(task, traits, base)
    before = _review(person, 4, (_window(0, 10),))
    assert before == probe.start_choices  # nothing changes until the episode is thought over
    # one change, to a choice that stops the pause (dropping its phases or its length)
    [change] = person.log
    assert (change["source"], change["episode"]) == ("feedback", 4)
    assert change["key"] in ("pause_at", "pause_steps") and change["to"] == UNSET
    assert person.choices == with_choice(probe.start_choices, change["key"], UNSET)
    # a window where the demonstrator does what the person does points at nothing
    now = imagine(task, calm(probe.motor, probe.choices), states)
    other = np.asarray(base.action[: len(states[0])])
    same = np.flatnonzero(np.all(np.abs(now[0] - other) < 1e-5, axis=1))
    start = int(same[same >= 70][0])
    assert np.all(np.abs(now[0][start : start + 10] - other[start : start + 10]) < 1e-5)
    person = SimulatedPerson(task, traits, base)
    _review(person, 4, (_window(start, start + 10),))
    assert person.choices == probe.start_choices and not person.log
    # the yaw: a demonstrator turning the wrist the other way, pointed at where it turns
    base = _demonstrator(task, probe, states, "yaw_offset", UNSET)
    person = SimulatedPerson(task, traits, base)
    _review(person, 4, (_window(60, 70),))
    assert [c["key"] for c in person.log] == ["yaw_offset"]
    assert person.choices.get("pause_at") == probe.start_choices["pause_at"]


def test_naive_person_only_gets_practice(states):
    from elicit_jax.sim.env import make_task

    task = make_task("square-nut")
    person = SimulatedPerson(task, parse_person("mild,noise=3,practice=0.5"), None)
    noise = []
    for i in range(4):
        person.on_event(_start(i, states[0][0]))
        noise.append(person.episode_style().noise)
        person.on_event(EpisodeEndEvent(i, "demonstration", True, 10, 10, True, None))
    assert noise[0] == pytest.approx(3 * person.motor.noise)
    assert noise == sorted(noise, reverse=True) and noise[-1] < 1.3 * person.motor.noise
    assert person.choices == person.start_choices and not person.log


# --- sessions ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def nut(square_nut_session_inputs) -> SessionInputs:
    """D_base, base policy and (λ, η) of square-nut, shared with the other session tests."""
    return square_nut_session_inputs


class Watcher:
    """Wraps a person; records its choices at every episode start and the reviews it got."""

    def __init__(self, inner):
        self.inner, self.name = inner, inner.name
        self.choices: dict[int, dict] = {}
        self.reviews: dict[int, ReviewEvent] = {}

    def on_event(self, event):
        if isinstance(event, EpisodeStartEvent):
            self.choices[event.episode] = dict(person_of(self.inner).choices)
        if isinstance(event, ReviewEvent):
            self.reviews[event.episode] = event
        self.inner.on_event(event)
        if isinstance(event, EpisodeStartEvent):
            self.choices[event.episode] = dict(person_of(self.inner).choices)

    def act(self, observation):
        return self.inner.act(observation)

    def catch_up(self, setup):
        self.inner.catch_up(setup)


def _session(nut, out, operator=PERSON, **kw):
    base = dict(
        task="square-nut",
        policy=str(nut.policy),
        base_demos=str(nut.base),
        lambda_=nut.lam,
        eta=nut.eta,
        operator=operator,
        demos=2,
        practice=1,
        prompt=2,
        max_episodes=6,
        seed=2,
    )
    setup, op, _ = open_session(SessionConfig(**{**base, **kw}), out)
    watcher = Watcher(op)
    session = run_session(setup, watcher)
    return session, watcher, person_of(op)


def _episodes(out):
    store = SessionStore(out)
    return [store.read_episode(int(h["index"])) for h in store.episode_headers()]


@pytest.fixture(scope="module")
def informed(nut, tmp_path_factory):
    out = tmp_path_factory.mktemp("informed") / "s"
    return out, *_session(nut, out)


def test_informed_person_moves_only_after_feedback_points_at_it(informed):
    _, session, watcher, person = informed
    assert person.log, "the conflicting person never changed"
    assert all(c["source"] == "feedback" for c in person.log)
    first = min(c["episode"] for c in person.log)
    episodes = sorted(watcher.choices)
    for e in episodes:
        if e <= first:  # unchanged up to and including the first episode given feedback
            assert watcher.choices[e] == person.start_choices
    for change in person.log:
        review = watcher.reviews[change["episode"]]
        assert review.verdict == "rejected" and review.feedback
        assert change["window"] in [[w.start, w.stop] for w in review.feedback]
        assert change["error_after"] < 0.8 * change["error_before"]
    assert session.progress.counts.accepted >= 1  # the changed person is accepted


def test_person_runs_unchanged_with_the_base_style_hidden(informed, nut, tmp_path, monkeypatch):
    out, _, _, person = informed
    mod = importlib.import_module("elicit_jax.sim.operators.square_nut")
    monkeypatch.setitem(mod.STYLES, "base", Poisoned())
    with pytest.raises(AssertionError, match="base operator's style was read"):
        mod.STYLES["base"][0]
    _, _, hidden = _session(nut, tmp_path / "hidden")
    assert hidden.log == person.log
    for a, b in zip(_episodes(out), _episodes(tmp_path / "hidden"), strict=True):
        np.testing.assert_array_equal(a.action, b.action)


def test_no_change_without_feedback_shown_or_in_naive_mode(nut, tmp_path):
    session, watcher, person = _session(
        nut, tmp_path / "no-feedback", show=("prompt", "indicator"), max_episodes=4
    )
    assert session.progress.counts.rejected >= 1 and not watcher.reviews
    assert not person.log and person.choices == person.start_choices
    session, watcher, person = _session(nut, tmp_path / "naive", mode="naive", max_episodes=3)
    assert session.progress.counts.accepted == 2
    assert not person.log and person.choices == person.start_choices
    assert person.episodes_done == 3


def test_resumed_person_continues_as_if_never_interrupted(informed, nut, tmp_path):
    out, _, _, person = informed
    _session(nut, tmp_path / "r", max_episodes=3)
    _, _, resumed = _session(nut, tmp_path / "r", max_episodes=6)
    assert resumed.log == person.log and resumed.choices == person.choices
    for a, b in zip(_episodes(out), _episodes(tmp_path / "r"), strict=True):
        np.testing.assert_array_equal(a.action, b.action)
