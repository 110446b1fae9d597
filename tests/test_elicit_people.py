"""Simulated people: their own parameters and motor traits, changed only by what they are shown.

Units (reach-pillar, ~40-step episodes): the person spec and populations; a fit moves θ towards
what the shown segments do; a person whose reachable set excludes the base operator's θ does
not end as base while the same person with full reach does; a person shown random actions at
D_base's states does not get closer to D_base; practice trials judged by success (the
naive arm). Sessions on square-nut (a tiny base policy, thresholds fitted on same-style vs
conflict-flip-pause demos): an informed person runs identically with the task's style list and
the base operator's style made unreadable, changes nothing before feedback, nothing when the
feedback is not shown, nothing in naive mode when it never tries, and resumes as if never
interrupted.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest
from fixtures_data import SessionInputs

from elicit_jax.elicit.events import (
    EpisodeEndEvent,
    EpisodeStartEvent,
    PromptEvent,
    ReviewEvent,
    SessionEndEvent,
)
from elicit_jax.elicit.people import SimulatedPerson, make_population, parse_person, person_of
from elicit_jax.elicit.people.learn import Shown, compass_search, imagined_error
from elicit_jax.elicit.people.traits import PersonTraits
from elicit_jax.elicit.run import run_session
from elicit_jax.elicit.setup import open_session
from elicit_jax.elicit.store import SessionStore
from elicit_jax.errors import ElicitError

PERSON = "person:conflict-flip-pause,imitation=0,uptake=1,explore=0,noise=0.06,practice=0.3,seed=5"


class Guarded(dict):
    """A task's style registry in which only ``allowed`` may be looked up: listing the styles
    or reading any other entry (the base operator's above all) fails the test."""

    def __init__(self, styles, allowed):
        super().__init__(styles)
        self.allowed = allowed

    def _fail(self, *_args, **_kw):
        raise AssertionError("the style list or another style was read")

    def __getitem__(self, key):
        if key != self.allowed:
            self._fail()
        return super().__getitem__(key)

    __iter__ = keys = values = items = __len__ = get = _fail


def test_person_spec_round_trip_and_errors():
    p = parse_person("mild,imitation=0.25,uptake=1,delay=2,memory=3,reach=0.5,seed=4")
    assert (p.style, p.imitation, p.uptake, p.seed, p.explore) == ("mild", 0.25, 1.0, 4, 0.3)
    assert (p.delay, p.memory, p.reach) == (2, 3, 0.5)
    assert parse_person(p.spec().partition(":")[2]) == p
    for bad, words in [
        ("mild,color=3", "trait=value"),
        ("mild,uptake=1.5", "uptake must be in [0, 1]"),
        ("mild,memory=0", "memory must be in [1, 1000]"),
        ("mild,speed=2", "speed must be in [0.05, 1.0]"),
        ("mild,seed=x", "seed needs a number"),
        ("mild,explore=nan", "explore must be finite"),
    ]:
        with pytest.raises(ElicitError, match=words.replace("[", r"\[").replace("]", r"\]")):
            parse_person(bad)
    q = parse_person("mild,noise=0.08,practice=0.5")
    assert q.noise_at(0) == pytest.approx(0.08)
    assert q.noise_at(1) == pytest.approx(0.08 * 1.5 / 2)  # halfway to half the noise


def test_population_is_seeded_with_spread():
    a = make_population(["same-style", "conflict-flip-pause"], 6, seed=3)
    assert a == make_population(["same-style", "conflict-flip-pause"], 6, seed=3)
    assert a != make_population(["same-style", "conflict-flip-pause"], 6, seed=4)
    assert [p.style for p in a] == ["same-style", "conflict-flip-pause"] * 3
    assert len({p.seed for p in a}) == 6
    for trait in ("imitation", "uptake", "explore", "noise", "speed", "gain", "reach"):
        values = [getattr(p, trait) for p in a]
        assert len(set(values)) == 6 and min(values) >= 0
    assert all(isinstance(p.delay, int) and 0 <= p.delay <= 3 for p in a)
    narrow = make_population(["mild"], 4, seed=0, ranges={"uptake": (0.5, 0.5)})
    assert {p.uptake for p in narrow} == {0.5}
    with pytest.raises(ElicitError, match="unknown trait range"):
        make_population(["mild"], 2, seed=0, ranges={"colour": (0, 1)})


def test_compass_search_finds_a_bounded_minimum():
    def f(x):
        return float((x[0] - 0.3) ** 2 + (x[1] + 2.0) ** 2)

    x, fx, evals = compass_search(f, np.array([0.9, 0.0]), np.array([0, -1.0]), np.array([1, 1.0]),
                                  max_evals=200)  # fmt: skip
    assert x == pytest.approx([0.3, -1.0], abs=0.02) and fx == pytest.approx(1.0, abs=0.02)
    assert evals <= 200


# --- units on reach-pillar ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def pillar():
    """reach-pillar, 4 base demos (the test reads the base operator; people never do) and the
    base operator's θ in the people's space."""
    from elicit_jax.sim.collect import CollectConfig, collect_episodes
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.operators import full_choices

    r = collect_episodes(
        CollectConfig(task="reach-pillar", operator="base", episodes=4, seed=11, batch=4)
    )
    shown = [Shown(ep["obs"].astype(float), ep["action"].astype(float)) for ep in r.episodes]
    task = make_task("reach-pillar")
    probe = SimulatedPerson(task, PersonTraits("mild"), None)
    return task, shown, probe.space.theta(full_choices("reach-pillar", "base"))


def _distance(person, theta):
    """Euclidean distance of θs, each coordinate as a fraction of its range."""
    return float(np.linalg.norm((person.theta - theta) / person.space.width))


def _watch_prompt(person, shown):
    from elicit_jax.elicit.events import PromptEpisode

    eps = tuple(PromptEpisode(i, s.states, s.actions, -1, 0.0) for i, s in enumerate(shown))
    person.on_event(PromptEvent(eps, "watch"))


def test_fit_follows_what_is_shown_within_reach(pillar):
    task, shown, base_theta = pillar
    spec = "conflict-right,imitation=1,reach={},slip=0,gain=1.2,speed=0.8,seed=3"
    free = SimulatedPerson(task, parse_person(spec.format(1.0)), None)
    boxed = SimulatedPerson(task, parse_person(spec.format(0.25)), None)
    assert free.start_choices["route"] == "right" and _distance(free, base_theta) > 0.4
    for person in (free, boxed):
        before = imagined_error(task, person.motor, person.space, person.theta, shown)
        _watch_prompt(person, shown)
        person.after = imagined_error(task, person.motor, person.space, person.theta, shown)
        person.before = before
    # full reach: it learns to pass on the left, near the base operator's parameters
    assert [c["source"] for c in free.log] == ["prompt"]
    # (measured 0.22 from 0.57: its lower gain is best matched by a wider arc than the base's)
    assert free.choices["route"] == "left" and _distance(free, base_theta) < 0.3
    assert free.after < 0.2 * free.before
    # the base's θ outside its reachable set: it cannot end as base, by θ or by its actions
    assert not boxed.bounds[0][0] <= base_theta[0] <= boxed.bounds[1][0]
    assert boxed.choices["route"] == "right" and _distance(boxed, base_theta) > 0.25
    assert boxed.after > 2 * free.after  # measured: 0.127 vs 0.047


def test_shown_random_segments_do_not_bring_a_person_closer_to_base(pillar):
    """Random actions at D_base's states carry no way of doing the task: fitting them must not
    bring the person's θ closer to the base operator's, nor make it act as D_base does (a
    person may learn to stand still from noise, which lowers a squared error against any
    moving demonstrator, so the imagined error is held to "not as base", not "no lower")."""
    task, shown, base_theta = pillar
    rng = np.random.default_rng(0)
    scrambled = [Shown(s.states, rng.uniform(-1, 1, s.actions.shape)) for s in shown]
    spec = "conflict-right,imitation=1,reach=1,slip=0,seed={}"
    learnt = 0
    for seed in range(3):
        person = SimulatedPerson(task, parse_person(spec.format(seed)), None)
        far = _distance(person, base_theta)
        _watch_prompt(person, scrambled)
        assert _distance(person, base_theta) >= 0.9 * far
        assert imagined_error(task, person.motor, person.space, person.theta, shown) > 0.1
        # the same person shown the real segments learns (a local search: not always)
        control = SimulatedPerson(task, parse_person(spec.format(seed)), None)
        _watch_prompt(control, shown)
        learnt += _distance(control, base_theta) < 0.5 * far
    assert learnt >= 2  # measured: 2 of 3 (seed 1 stops at a local minimum, lateral ≈ 0)


def test_practice_trials_are_judged_by_success(pillar):
    """The naive arm: a person who fails tries a perturbed θ, keeps it after a success, goes
    back after a failure; one who succeeds, or never explores, stays."""
    task, shown, _ = pillar
    obs = shown[0].states[0]

    def episode(person, i, success):
        person.on_event(EpisodeStartEvent(i, "practice", obs, 1, i, 100, False, False))
        person.on_event(EpisodeEndEvent(i, "practice", success, 40, 40, False, None))

    person = SimulatedPerson(task, parse_person("conflict-right,explore=1,seed=2"), None)
    start = person.theta.copy()
    episode(person, 0, False)
    episode(person, 1, False)  # thinking over episode 0 starts a trial
    assert [c["source"] for c in person.log] == ["practice-try"]
    tried = person.theta.copy()
    assert not np.allclose(tried, start)
    episode(person, 2, True)  # episode 1 failed with the trial: back to the start
    assert person.log[-1]["source"] == "practice-undo" and np.allclose(person.theta, start)
    episode(person, 3, True)  # episode 2 succeeded: nothing to try
    assert len(person.log) == 2
    person = SimulatedPerson(task, parse_person("conflict-right,explore=1,seed=2"), None)
    episode(person, 0, False)
    episode(person, 1, True)
    episode(person, 2, True)  # the trial's episode succeeded: kept
    assert [c["source"] for c in person.log] == ["practice-try", "practice-keep"]
    assert np.allclose(person.theta, tried)
    calm = SimulatedPerson(task, parse_person("conflict-right,explore=0,seed=2"), None)
    for i in range(4):
        episode(calm, i, False)
    assert not calm.log and np.allclose(calm.theta, calm.start_theta)
    # a failed last episode starts no trial: the θ a session ends with was acted with
    person = SimulatedPerson(task, parse_person("conflict-right,explore=1,seed=2"), None)
    episode(person, 0, False)
    person.on_event(SessionEndEvent("complete", None))
    assert not person.log and np.allclose(person.theta, person.start_theta)


def test_memory_keeps_the_last_segments_and_delay_acts_on_old_states(pillar):
    from elicit_jax.elicit.events import Observation

    task, shown, _ = pillar
    person = SimulatedPerson(task, parse_person("conflict-right,imitation=0,memory=2"), None)
    _watch_prompt(person, shown)  # 4 demonstrations shown, 2 remembered: the last two
    assert len(person.memory) == 2 and person.memory[0].states is shown[2].states
    states = shown[0].states[:12]

    def actions(spec):
        p = SimulatedPerson(task, parse_person(spec), None)
        p.theta[p.space.names.index("pause")] = 0.0  # moving from the first step
        p.on_event(EpisodeStartEvent(0, "practice", states[0], 1, 0, 100, False, False))
        obs = [Observation(o, t, 0, "practice", False, None, True) for t, o in enumerate(states)]
        return np.array([p.act(o) for o in obs])

    late = actions("conflict-right,delay=3,noise=0,seed=1")
    prompt = actions("conflict-right,delay=0,noise=0,seed=1")
    # delay 3: the first 4 steps act on the first state; then on the state 3 steps back
    np.testing.assert_allclose(late[:4], np.repeat(prompt[:1], 4, 0), atol=1e-9)
    assert not np.allclose(late[4:8], prompt[4:8])


def test_a_person_cannot_start_as_base():
    from elicit_jax.sim.env import make_task

    with pytest.raises(ElicitError, match="cannot start from the base"):
        SimulatedPerson(make_task("square-nut"), PersonTraits("base"), None)


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
    config = nut.session_config(operator, **{"max_episodes": 6, "seed": 2, **kw})
    setup, op, _ = open_session(config, out)
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
    _, _, watcher, person = informed
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
        assert change["error_after"] < 0.8 * change["error_before"]


def test_person_runs_unchanged_with_the_style_list_and_base_hidden(
    informed, nut, tmp_path, monkeypatch
):
    out, _, _, person = informed
    mod = importlib.import_module("elicit_jax.sim.operators.square_nut")
    monkeypatch.setattr(mod, "STYLES", Guarded(mod.STYLES, "conflict-flip-pause"))
    # the operator class's defaults are the base operator's choices: unreadable too
    monkeypatch.setattr(mod, "DEFAULT_CHOICES", Guarded(mod.DEFAULT_CHOICES, None))
    for reach_for_it in (lambda: mod.STYLES["base"], lambda: list(mod.STYLES)):
        with pytest.raises(AssertionError, match="style list or another style"):
            reach_for_it()
    _, _, hidden = _session(nut, tmp_path / "hidden")
    assert hidden.log == person.log
    for a, b in zip(_episodes(out), _episodes(tmp_path / "hidden"), strict=True):
        np.testing.assert_array_equal(a.action, b.action)


def test_no_change_without_feedback_shown_or_in_naive_mode(nut, tmp_path):
    session, watcher, person = _session(
        nut, tmp_path / "no-feedback", show=("prompt", "indicator"), max_episodes=4
    )
    assert session.progress.counts.rejected >= 1 and not watcher.reviews
    assert not person.log and person.choices == person.start_choices  # imitation 0, explore 0
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


def test_person_with_every_channel_open_learns_from_the_prompt_first(nut, tmp_path):
    """Not the feedback-only settings above: imitation 1 and explore 1. The prompt comes before
    the first demonstration, so the first change is the prompt's, and it turns the wrist
    towards the prompt's way (away from its starting half turn); the feedback's comes next."""
    spec = "person:conflict-flip-pause,imitation=1,uptake=1,explore=1,reach=1,slip=0.01,seed=5"
    session, _, person = _session(nut, tmp_path / "open", operator=spec, max_episodes=4)
    sources = [c["source"] for c in person.log]
    assert sources[:2] == ["prompt", "feedback"], sources
    first_demo = min(r.index for r in _episodes(tmp_path / "open") if r.kind == "demonstration")
    assert person.log[0]["episode"] <= first_demo
    assert abs(person.log[0]["to"]["yaw_offset"]) < abs(person.log[0]["from"]["yaw_offset"]) - 1
    assert set(sources) <= {"prompt", "feedback", "practice-try", "practice-keep", "practice-undo"}
    # having turned the wrist round before demonstrating, then dropped the pauses its feedback
    # pointed at, its demonstrations are far less incompatible than its practice episode
    # (measured 78% → 31%, 6%, 9%: starting from the prior, not the base, it is not yet within
    # the 5% rule after 4 episodes, as it was when it started at the base's grasp and carry)
    fractions = [float(np.mean(r.incompatible)) for r in _episodes(tmp_path / "open")]
    assert max(fractions[1:]) < 0.5 * fractions[0] and min(fractions[1:]) < 0.1 * fractions[0]
    assert session.progress.counts.episodes == 4


# --- the shipped study's hammer-drawer people can do the task -----------------------------------
def test_shipped_hammer_drawer_same_style_person_completes_the_task():
    """p3 of the shipped hammer-drawer population (same-style) completes the task with its own
    controller, delay and noise (with [people.ranges] alone it drew delay 1 × gain 2.04 and
    oscillated at the grasp in every episode); the task's narrower ranges touch no other task."""
    from elicit_jax.pipeline.elicitation.spec import load_study
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.rollout_mujoco import BatchSim

    study = load_study("pipelines/elicitation.toml", "cpu")
    people = {t.name: t.people for t in study.tasks}
    assert people["reach-pillar"][3].endswith("gain=2.037,delay=1,memory=3,reach=0.835,"
                                              "slip=0.032,seed=3")  # fmt: skip
    task = make_task("hammer-drawer")
    person = SimulatedPerson(task, parse_person(people["hammer-drawer"][3][len("person:") :]), None)
    assert person.traits.style == "same-style" and person.traits.delay <= 1
    op = importlib.import_module("elicit_jax.sim.operators").make_operator(
        task, person.name, style=person.episode_style()
    )
    with BatchSim(task, 4, threads=1) as sim:
        obs = sim.reset_seeds(np.arange(4) + 500)
        op.reset(obs, np.random.default_rng(1))
        history, done = [obs], np.zeros(4, bool)
        for _ in range(task.config.horizon):
            obs = sim.step(op.act(history[max(len(history) - 1 - person.traits.delay, 0)]),
                           active=~done)  # fmt: skip
            history.append(obs)
            done |= sim.success
    assert done.sum() >= 3


# --- where people start: the task's prior, not the base operator's θ ----------------------------
def _shipped_tasks():
    """(task, starting styles, contrast-set style) of the shipped elicitation study."""
    from elicit_jax.pipeline.elicitation.spec import load_study

    study = load_study("pipelines/elicitation.toml", "cpu")
    styles = {t.name: [p.split(",")[0].removeprefix("person:") for p in t.people] for t in
              study.tasks}  # fmt: skip
    return [(t.name, styles[t.name], t.incompatible_operator) for t in study.tasks]


def _base_theta(task):
    from elicit_jax.elicit.people.space import space_of
    from elicit_jax.sim.operators import full_choices

    return space_of(task).theta(full_choices(task, "base"))


def _starts(task, styles, n=60, seed=0):
    from elicit_jax.elicit.people.person import start_theta

    return [start_theta(task, p) for p in make_population(styles, n, seed)]


def _old_starts(task, styles, n=60, seed=0):
    """People built the old way: the style's choices, the operator class's defaults (the base
    operator's) for the rest, plus 3% jitter; same-style is the base plus jitter."""
    from elicit_jax.elicit.people.space import space_of
    from elicit_jax.sim.operators import full_choices

    space = space_of(task)
    out = []
    for p in make_population(styles, n, seed):
        own = space.theta(full_choices(task, p.style))
        rng = np.random.default_rng([p.seed, 31])
        out.append(space.clip(own + rng.normal(0.0, 0.03 * space.width)))
    return out


def starts_far_from_base(task, starts, pairs=400):
    """The check: on every coordinate, and overall, the mean distance of the starting θs from
    the base's is no smaller than the mean distance between two independent prior draws."""
    from elicit_jax.elicit.people.space import space_of

    space, base = space_of(task), _base_theta(task)
    rng = np.random.default_rng(1)
    between = np.mean([space.differences(space.prior_draw(rng), space.prior_draw(rng))
                       for _ in range(pairs)], axis=0)  # fmt: skip
    from_base = np.mean([space.differences(t, base) for t in starts], axis=0)
    far = bool(np.all(from_base >= between) and from_base.mean() >= between.mean())
    return far, from_base.round(3).tolist(), between.round(3).tolist()


def test_people_start_no_nearer_the_base_than_two_prior_draws():
    for task, styles, _ in _shipped_tasks():
        far, from_base, between = starts_far_from_base(task, _starts(task, styles))
        assert far, (task, from_base, between)


def test_no_prior_is_centred_on_the_base():
    """Per coordinate, the prior's mean (an angle's: its circular mean) is at least 5% of the
    largest difference away from the base operator's value."""
    from elicit_jax.elicit.people.space import space_of

    for task, _, _ in _shipped_tasks():
        space, base = space_of(task), _base_theta(task)
        rng = np.random.default_rng(2)
        draws = np.array([space.prior_draw(rng) for _ in range(2000)])
        mean = draws.mean(axis=0)
        for i, name in enumerate(space.names):
            if name in space.angular:
                mean[i] = np.angle(np.exp(1j * draws[:, i]).mean())
        gaps = space.differences(mean, base)
        assert (gaps >= 0.05).all(), (task, dict(zip(space.names, gaps.round(3), strict=True)))


def test_people_built_the_old_way_fail_the_distance_check():
    """The planted case: start at the base operator's θ wherever the style is silent."""
    for task, styles, _ in _shipped_tasks():
        far, from_base, between = starts_far_from_base(task, _old_starts(task, styles))
        assert not far, (task, from_base, between)


def test_coordinates_a_style_leaves_open_do_not_start_at_the_base():
    from elicit_jax.elicit.people.space import space_of
    from elicit_jax.sim.operators import style_of

    for task, styles, _ in _shipped_tasks():
        space, base = space_of(task), _base_theta(task)
        for style in set(styles) - {"same-style"}:
            pinned = space.regions(style_of(task, style).choices)
            open_ = [n for n in space.names if n not in pinned]
            for theta in _starts(task, [style], n=20):
                gaps = space.differences(theta, base)
                assert all(gaps[space.names.index(n)] > 1e-9 for n in open_), (task, style, theta)


def test_the_compatible_person_starts_at_its_stated_distance_with_the_base_choices():
    """same-style is no longer the base plus jitter: its θ is stated per task (docs/people.md
    gives the distances 0.10, 0.10, 0.08) and makes the base's discrete choices."""
    from elicit_jax.elicit.people.person import start_theta
    from elicit_jax.elicit.people.space import space_of
    from elicit_jax.sim.operators import full_choices

    stated = {"reach-pillar": 0.10, "round-nut": 0.10, "square-nut": 0.10, "hammer-drawer": 0.08}
    for task, distance in stated.items():
        space = space_of(task)
        for seed in (0, 7):
            theta = start_theta(task, PersonTraits("same-style", seed=seed))
            np.testing.assert_array_equal(theta, space.compatible)
            assert round(space.distance(theta, _base_theta(task)), 2) == distance
        base = full_choices(task, "base")
        mine = space.choices(space.compatible)
        for key in ("route", "approach", "carry", "place_yaw"):
            assert mine.get(key) == base.get(key, mine.get(key)), (task, key)


def test_the_contrast_style_is_no_persons_start():
    """The threshold fit's known-incompatible style: not a starting style by name, and no
    person of a large draw starts within the region its choices pin down."""
    from elicit_jax.pipeline.elicitation.spec import starts_from

    for task, styles, contrast in _shipped_tasks():
        assert contrast not in styles
        assert not any(starts_from(task, contrast, t) for t in _starts(task, styles, n=120)), task
        # the region check itself: the contrast style's own θ is inside it
        from elicit_jax.elicit.people.space import space_of
        from elicit_jax.sim.operators import full_choices

        assert starts_from(task, contrast, space_of(task).theta(full_choices(task, contrast)))


def test_a_study_whose_contrast_is_a_persons_own_way_is_refused():
    """The planted case: round-nut's old contrast set, conflict-flip, is the flip 2 of its
    people start from (conflict-flip-pause and conflict-flip-tip)."""
    import tomllib

    from elicit_jax.pipeline.elicitation.spec import parse_study

    with open("pipelines/elicitation.toml") as f:
        text = f.read()
    old = text.replace('incompatible_operator = "conflict-hold"',
                       'incompatible_operator = "conflict-flip"', 1)  # fmt: skip
    assert old != text
    with pytest.raises(ElicitError, match="starts from the way of incompatible_operator"):
        parse_study(tomllib.loads(old))


def test_a_start_reads_neither_the_base_nor_the_operator_defaults(monkeypatch):
    from elicit_jax.elicit.people.person import start_theta

    for task, styles, _ in _shipped_tasks():
        mod = importlib.import_module(f"elicit_jax.sim.operators.{task.replace('-', '_')}")
        for style in set(styles):
            with monkeypatch.context() as m:
                m.setattr(mod, "STYLES", Guarded(mod.STYLES, style))
                m.setattr(mod, "DEFAULT_CHOICES", Guarded(mod.DEFAULT_CHOICES, None))
                base_mod = importlib.import_module("elicit_jax.sim.operators.base")
                m.setattr(base_mod, "NO_PAUSE", Guarded(base_mod.NO_PAUSE, None))
                start_theta(task, PersonTraits(style, seed=3))
