"""A simulated person behind the session interface: it acts in a style and learns only from
what the interface shows (the model is written down in ``docs/people.md``).

The person acts like a scripted operator of its current style, with motor noise that practice
reduces. Between episodes it thinks over what it saw (:class:`Seen`) and may change a style
*choice* (one key of the style's choices; two at once when no single change is enough):

* **prompt** (:meth:`SimulatedPerson.learn_from_prompt`): it imagines doing the shown base
  demonstrations its own way and each single-choice change of its way
  (:func:`~elicit_jax.elicit.people.imagine.imagine`); while some change predicts the shown
  actions clearly better (error down by more than :data:`MIN_GAIN`), it adopts the best one
  with probability ``imitation`` (and stops at the first it does not adopt);
* **feedback** (rejections, informed mode): for each flagged window, with probability
  ``uptake``, it watches the retrieved base demonstration up to the end of the matched
  segment and adopts the single-choice change that best predicts the base's actions *on that
  segment*, weighing the action dimensions the explanation names (:data:`FOCUS`), again only
  for a clear gain;
* **live indicator**: after a demonstration whose light was red at more steps than the rule
  allows, with probability ``explore`` it tries another way: a single-choice change drawn
  with probability proportional to the number of red steps at which, replaying its own
  episode in imagination, the change would have acted differently (:func:`red_matters`) —
  the light says *where*, not *what*. It does not experiment with a choice it changed on the
  prompt's or the feedback's evidence. On the next lit demonstration it keeps the change if
  the task was done and the red fraction fell clearly (by :data:`MIN_GAIN`) below its mean
  since the last change, else it goes back and does not try that change again until some
  other change has stuck.

It never reads the base operator's style: the repertoire of choices comes from the task's
other styles (:func:`~elicit_jax.elicit.people.imagine.repertoire`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from elicit_jax.elicit.events import (
    DEMONSTRATION,
    EpisodeEndEvent,
    EpisodeStartEvent,
    Event,
    IndicatorEvent,
    Observation,
    PromptEvent,
    ReviewEvent,
    SessionEndEvent,
    WindowFeedback,
    to_jsonable,
)
from elicit_jax.elicit.people.imagine import (
    BASE_STYLE,
    UNSET,
    action_error,
    alternatives,
    calm,
    imagine,
    pairs,
    repertoire,
    same_value,
    with_choice,
)
from elicit_jax.elicit.people.traits import PersonTraits
from elicit_jax.errors import ElicitError

MIN_GAIN = 0.2
"""A change counts as better when it cuts the imagined action error (or, for a trial, the red
fraction) by more than this fraction."""
ERROR_FLOOR = 0.01
"""Below this imagined action error (per dim, squared) the person sees nothing to correct."""
FOCUS = 4.0
"""Weight of the action dimensions a window's explanation names (others weigh 1)."""
FOCUS_TOP = 2
"""How many of the explanation's action dimensions (largest difference first) it heeds."""
DIVERGE = 0.2
"""Imagined actions further apart than this (L2) count as a change that matters there."""


@dataclasses.dataclass
class Seen:
    """What the person saw of one episode (all of it from the interface).

    Attributes:
      index: the session's episode index.
      kind: ``practice`` or ``demonstration``.
      indicator: the live indicator was shown.
      segments: ``(first step, states (n, O))`` of each run of steps it controlled.
      red: step -> the indicator was red there (shown steps only).
      allowed: incompatible steps the rule allowed at the end (the indicator's count).
      feedback: the flagged windows of a rejection it was shown (else empty).
      success: the task was completed (the interface shows it).
    """

    index: int
    kind: str
    indicator: bool = False
    segments: list[tuple[int, list[np.ndarray]]] = dataclasses.field(default_factory=list)
    red: dict[int, bool] = dataclasses.field(default_factory=dict)
    allowed: float = 0.0
    feedback: tuple[WindowFeedback, ...] = ()
    success: bool = False

    @property
    def n_red(self) -> int:
        return int(sum(self.red.values()))

    @property
    def red_fraction(self) -> float:
        return self.n_red / max(len(self.red), 1)


@dataclasses.dataclass
class Trial:
    """A change the person is trying because of the indicator."""

    key: str
    old: Any
    new: Any
    red_before: float
    episode: int


class SimulatedPerson:
    """A :class:`~elicit_jax.elicit.events.SessionOperator` modelling a person who learns.

    Args:
      task: the simulated task.
      traits: who the person is.
      base: the base demonstrations; the person looks up only the one a feedback window names
        (the interface shows it).
      known: the repertoire of choices (default: :func:`repertoire` of the task).
    """

    def __init__(
        self,
        task: Any,
        traits: PersonTraits,
        base: Any,
        known: Mapping[str, list[Any]] | None = None,
    ) -> None:
        from elicit_jax.sim.operators import style_of

        if traits.style == BASE_STYLE:
            raise ElicitError(
                "a simulated person cannot start from the base operator's style "
                "(start from same-style for a compatible person)"
            )
        self.task = task
        self.traits = traits
        self.name = traits.spec().partition(":")[2]
        self.base = base
        self.motor = style_of(task.name, traits.style)
        self.choices: dict[str, Any] = dict(self.motor.choices)
        self.start_choices = dict(self.choices)
        self.known = {k: list(v) for k, v in (known or repertoire(task.name)).items()}
        for key, value in self.choices.items():  # its own ways are known to it
            values = self.known.setdefault(key, [UNSET])
            if not any(same_value(value, v) for v in values):
                values.append(value)
        self.episodes_done = 0
        self.trial: Trial | None = None
        self.tabu: list[tuple[str, Any]] = []
        self.anchored: set[str] = set()
        self.reds: list[float] = []
        self.log: list[dict[str, Any]] = []
        self.prompt_seen = False
        self._seen: Seen | None = None
        self._inner: Any = None
        self._rng = np.random.default_rng(0)
        self._base_rows: dict[int, tuple[int, int]] | None = None

    # --- acting ------------------------------------------------------------------------------
    def episode_style(self) -> Any:
        """The style it acts with now: its choices, noise scaled by how much it practised."""
        m = self.traits.noise_multiplier(self.episodes_done)
        s = self.motor
        return dataclasses.replace(
            s,
            choices=tuple(self.choices.items()),
            noise=s.noise * m,
            hesitate_prob=min(s.hesitate_prob * m, 1.0),
            jitter=s.jitter * m,
        )

    def restart(self, obs: np.ndarray) -> None:
        """Start its phases again from state ``obs (O,)`` (an HG-DAgger takeover)."""
        self._inner.reset(np.asarray(obs, np.float64)[None], self._rng)

    def act(self, observation: Observation) -> np.ndarray:
        if self._inner is None or self._seen is None:
            raise ElicitError("the simulated person was asked to act before an episode started")
        obs = np.asarray(observation.obs, np.float32)
        segs = self._seen.segments
        if not segs or segs[-1][0] + len(segs[-1][1]) != observation.step:
            segs.append((observation.step, []))
        segs[-1][1].append(obs.copy())
        return self._inner.act(obs.astype(np.float64)[None])[0]

    def on_event(self, event: Event) -> None:
        from elicit_jax.sim.operators import make_operator

        if isinstance(event, PromptEvent):
            self.learn_from_prompt(event)
        elif isinstance(event, EpisodeStartEvent):
            self.digest()
            self._rng = np.random.default_rng(event.operator_seed)
            self._inner = make_operator(self.task, self.name, style=self.episode_style())
            self._inner.reset(np.asarray(event.obs, np.float64)[None], self._rng)
            self._seen = Seen(event.episode, event.episode_kind, indicator=event.indicator)
        elif isinstance(event, IndicatorEvent) and self._seen is not None:
            self._seen.red[event.step] = bool(event.incompatible)
            self._seen.allowed = float(event.allowed)
        elif isinstance(event, EpisodeEndEvent) and self._seen is not None:
            self._seen.success = bool(event.success)
        elif isinstance(event, ReviewEvent) and self._seen is not None:
            self._seen.feedback = tuple(event.feedback)
        elif isinstance(event, SessionEndEvent):
            self.digest()

    # --- learning ----------------------------------------------------------------------------
    def _note(self, episode: int, source: str, key: str, old: Any, new: Any, **extra: Any) -> None:
        self.log.append(
            {"episode": episode, "source": source, "key": key, "from": old, "to": new, **extra}
        )

    def _adopt(self, episode: int, source: str, key: str, value: Any, **extra: Any) -> None:
        if source in ("prompt", "feedback"):
            self.anchored.add(key)
        old = self.choices.get(key, UNSET)
        self.choices = with_choice(self.choices, key, value)
        self._note(episode, source, key, old, value, **extra)

    def _best_change(
        self,
        states: list[np.ndarray],
        actions: list[np.ndarray],
        spans: list[slice] | None = None,
        weights: np.ndarray | None = None,
    ) -> tuple[tuple[tuple[str, Any], ...], float, float] | None:
        """The change of one choice (or, when none is enough, of two) that best predicts
        ``actions`` at ``states``, if clearly better than the current choices:
        ``(((key, value), ...), error now, error after)``."""

        def error(choices: Mapping[str, Any]) -> float:
            imagined = imagine(self.task, calm(self.motor, choices), states)
            return action_error(imagined, actions, spans, weights)

        now = error(self.choices)
        if now <= ERROR_FLOOR:
            return None
        singles = ((((k, v),), new) for k, v, new in alternatives(self.choices, self.known))
        for candidates in (singles, pairs(self.choices, self.known)):
            best: tuple[tuple, float] | None = None
            for changes, new in candidates:
                err = error(new)
                if best is None or err < best[1]:
                    best = (changes, err)
            if best is not None and best[1] < (1.0 - MIN_GAIN) * now:
                return best[0], now, best[1]
        return None

    def learn_from_prompt(self, event: PromptEvent) -> None:
        """Imitate the prompt's demonstrations (once: a repeated prompt teaches nothing new)."""
        if self.prompt_seen or not event.episodes:
            return
        self.prompt_seen = True
        rng = np.random.default_rng([self.traits.seed, 1_000_003])
        states = [np.asarray(e.obs, np.float64) for e in event.episodes]
        actions = [np.asarray(e.action, np.float64) for e in event.episodes]
        episode = self._seen.index + 1 if self._seen is not None else 0
        for _ in range(len(self.known)):
            change = self._best_change(states, actions)
            if change is None or rng.random() >= self.traits.imitation:
                break
            changes, now, after = change
            for key, value in changes:
                self._adopt(episode, "prompt", key, value, error_before=now, error_after=after)

    def digest(self) -> None:
        """Think over the episode just finished (called when the next one starts)."""
        seen, self._seen = self._seen, None
        if seen is None:
            return
        self.episodes_done += 1
        if seen.kind != DEMONSTRATION:
            return
        rng = np.random.default_rng([self.traits.seed, seen.index, 17])
        if self.trial is not None and seen.indicator:
            self._settle_trial(seen)
        elif seen.indicator:
            self.reds.append(seen.red_fraction)
        changed = self._learn_from_feedback(seen, rng) if seen.feedback else False
        if changed:
            self.reds = []
        too_red = seen.indicator and seen.n_red > seen.allowed
        if not changed and too_red and self.trial is None and rng.random() < self.traits.explore:
            self._start_trial(seen, rng)

    def _settle_trial(self, seen: Seen) -> None:
        trial, self.trial = self.trial, None
        assert trial is not None
        detail = {"red_before": trial.red_before, "red_after": seen.red_fraction}
        if not seen.success or seen.red_fraction >= (1.0 - MIN_GAIN) * trial.red_before:
            self._adopt(seen.index, "indicator-undo", trial.key, trial.old, **detail)
            self.tabu.append((trial.key, trial.new))
        else:
            self._note(seen.index, "indicator-keep", trial.key, trial.new, trial.new, **detail)
            self.tabu, self.reds = [], [seen.red_fraction]

    def _base_segment(self, base_episode: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
        """The shown base demonstration's states and actions, from its start to ``stop``."""
        if self._base_rows is None:
            self._base_rows = {int(e): (s, t) for e, s, t in self.base.episode_bounds()}
        if base_episode not in self._base_rows:
            raise ElicitError(f"feedback names base demonstration {base_episode}, not in D_base")
        s, t = self._base_rows[base_episode]
        end = min(s + stop, t)
        return (
            np.asarray(self.base.obs[s:end], np.float64),
            np.asarray(self.base.action[s:end], np.float64),
        )

    def _learn_from_feedback(self, seen: Seen, rng: np.random.Generator) -> bool:
        from elicit_jax.sim.env import ACTION_NAMES

        changed = False
        for window in seen.feedback:
            if rng.random() >= self.traits.uptake:
                continue
            states, actions = self._base_segment(window.base_episode, window.base_stop)
            weights = np.ones(len(ACTION_NAMES))
            named = [a.name for a in window.actions[:FOCUS_TOP] if a.difference > 0]
            for name in named:
                if name in ACTION_NAMES:
                    weights[ACTION_NAMES.index(name)] = FOCUS
            span = slice(window.base_start, window.base_stop)
            change = self._best_change([states], [actions], [span], weights)
            if change is None:
                continue
            changes, now, after = change
            for key, value in changes:
                self._adopt(seen.index, "feedback", key, value, window=[window.start, window.stop],
                            base_episode=window.base_episode, error_before=now,
                            error_after=after)  # fmt: skip
            changed = True
        return changed

    def _start_trial(self, seen: Seen, rng: np.random.Generator) -> None:
        options = [
            (key, value, n)
            for key, value, n in red_matters(self, seen)
            if n
            and key not in self.anchored
            and not any(k == key and same_value(v, value) for k, v in self.tabu)
        ]
        if not options:
            return
        weights = np.array([n for _, _, n in options], float)
        key, value, _ = options[int(rng.choice(len(options), p=weights / weights.sum()))]
        before = float(np.mean(self.reds)) if self.reds else seen.red_fraction
        self.trial = Trial(key, self.choices.get(key, UNSET), value, before, seen.index)
        self.reds = []
        self._adopt(seen.index, "indicator-try", key, value, red_before=before)

    # --- resume and report -----------------------------------------------------------------------
    def catch_up(self, setup: Any) -> None:
        """Relive a resumed session's finished episodes from their records, so the person
        resumes in the state an uninterrupted session would have left it in."""
        config = setup.config
        for header in setup.store.episode_headers():
            rec = setup.store.read_episode(int(header["index"]))
            if rec.kind == DEMONSTRATION and config.prompt and config.shown("prompt"):
                self.learn_from_prompt(setup.prompt_event())
            self.digest()
            self._seen = seen_from_record(rec, config, setup.rule)

    def summary(self) -> dict[str, Any]:
        """JSON-ready: who it is, its starting and current choices and every change."""
        return to_jsonable(
            {
                "person": self.traits.spec(),
                "traits": dataclasses.asdict(self.traits),
                "start_choices": self.start_choices,
                "choices": self.choices,
                "episodes_done": self.episodes_done,
                "changes": self.log,
                "repertoire": self.known,
            }
        )


def red_matters(person: SimulatedPerson, seen: Seen) -> list[tuple[str, Any, int]]:
    """Each single-choice change ``(key, value, n)``, with ``n`` the red steps of ``seen`` at
    which the person, replaying its own states in imagination with that change, would have
    acted differently (imagined actions more than :data:`DIVERGE` apart)."""
    starts = [first for first, _ in seen.segments]
    states = [np.asarray(s, np.float64) for _, s in seen.segments]
    if not states:
        return []
    red = {t for t, r in seen.red.items() if r}
    now = imagine(person.task, calm(person.motor, person.choices), states)
    out = []
    for key, value, new in alternatives(person.choices, person.known):
        other = imagine(person.task, calm(person.motor, new), states)
        n = 0
        for first, a, b in zip(starts, now, other, strict=True):
            far = np.flatnonzero(np.linalg.norm(a - b, axis=1) > DIVERGE) + first
            n += len(red.intersection(far.tolist()))
        out.append((key, value, n))
    return out


def seen_from_record(rec: Any, config: Any, rule: Any) -> Seen:
    """What the person saw of a recorded episode (for :meth:`SimulatedPerson.catch_up`)."""
    op = np.asarray(rec.operator, bool)
    indicator = rec.kind == DEMONSTRATION and config.shown("indicator")
    seen = Seen(rec.index, rec.kind, indicator=indicator, success=bool(rec.success))
    edges = np.flatnonzero(np.diff(np.concatenate([[0], op.astype(int), [0]])))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        seen.segments.append((int(a), [np.asarray(o, np.float32) for o in rec.obs[a:b]]))
    if indicator:
        scored = np.flatnonzero(rec.scored)
        seen.red = {int(t): bool(rec.incompatible[t]) for t in scored}
        seen.allowed = float(rule.allowed(len(scored)))
    if rec.feedback_shown and rec.verdict == "rejected":
        seen.feedback = tuple(rec.feedback)
    return seen
