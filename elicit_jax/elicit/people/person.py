"""A simulated person behind the session interface: the task's phase machine driven by its own
parameters θ and motor traits, changing θ only from what the interface shows (the model is
written down in ``docs/people.md``).

* **acting**: the task's operator class with the choices θ maps to
  (:mod:`~elicit_jax.elicit.people.space`), the person's own speed, gain and motor noise
  (practice lowers the noise), acting on the state ``delay`` steps ago;
* **prompt and feedback** (:meth:`SimulatedPerson.learn_from_prompt`, feedback on a
  rejection): the shown base segments enter a memory of the last ``memory`` segments; the
  person fits θ to them (:func:`~elicit_jax.elicit.people.learn.fit_theta`: compass search
  within its reachable bounds minimising the imagined action error) and adopts the fit, with
  an execution slip, when it predicts the remembered actions clearly better (by
  :data:`MIN_GAIN`);
* **practice** (what every mode shows: its own success, and the live indicator's red steps
  when shown): after a failed (or too red) episode, with probability ``explore``, it tries a
  random perturbation of θ; the next episode keeps it if it succeeded (and was clearly less
  red), else the person goes back.

It starts from θ drawn from its task's prior, restricted to what its starting style's choices
pin down (:func:`start_theta`); it reads its starting style's choices only, never the base
operator's style nor the task's list of styles.
"""

from __future__ import annotations

import collections
import dataclasses
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
from elicit_jax.elicit.people.learn import Shown, fit_theta
from elicit_jax.elicit.people.space import space_of
from elicit_jax.elicit.people.traits import PersonTraits
from elicit_jax.errors import ElicitError
from elicit_jax.sim.operators import Style

BASE_STYLE = "base"
"""The base operator's registry name: a person never starts from (or reads) it."""
MIN_GAIN = 0.2
"""A fit is adopted when it cuts the imagined action error (a trial: the red fraction) by more
than this fraction."""
ERROR_FLOOR = 0.01
"""Below this imagined action error (per dim, squared) the person sees nothing to correct."""
FOCUS = 4.0
"""Weight of the action dimensions a window's explanation names (others weigh 1)."""
FOCUS_TOP = 2
"""How many of the explanation's action dimensions (largest difference first) it heeds."""
COMPATIBLE_STYLE = "same-style"
"""The compatible person's starting style: it starts at its space's stated ``compatible`` θ
(:attr:`~elicit_jax.elicit.people.space.ParamSpace.compatible`), read from no operator."""
TRIAL_STEP = 0.15
"""Std of a practice trial's perturbation of θ, as a fraction of each range."""


@dataclasses.dataclass
class Seen:
    """What the person saw of one episode (all of it from the interface).

    Attributes:
      index: the session's episode index.
      kind: ``practice`` or ``demonstration``.
      indicator: the live indicator was shown.
      red: step -> the indicator was red there (shown steps only).
      allowed: incompatible steps the rule allowed at the end (the indicator's count).
      feedback: the flagged windows of a rejection it was shown (else empty).
      success: the task was completed (the interface shows it).
    """

    index: int
    kind: str
    indicator: bool = False
    red: dict[int, bool] = dataclasses.field(default_factory=dict)
    allowed: float = 0.0
    feedback: tuple[WindowFeedback, ...] = ()
    success: bool = False

    @property
    def red_fraction(self) -> float:
        return int(sum(self.red.values())) / max(len(self.red), 1)

    @property
    def bad(self) -> bool:
        """Failed, or (indicator shown) red at more steps than the rule allows."""
        return not self.success or (self.indicator and sum(self.red.values()) > self.allowed)


class SimulatedPerson:
    """A :class:`~elicit_jax.elicit.events.SessionOperator` modelling a person who learns.

    Args:
      task: the simulated task.
      traits: who the person is.
      base: the base demonstrations; the person looks up only the one a feedback window names
        (the interface shows it).
    """

    def __init__(self, task: Any, traits: PersonTraits, base: Any) -> None:
        self.task, self.traits, self.base = task, traits, base
        self.name = traits.spec().partition(":")[2]
        self.space = space_of(task.name)
        width = self.space.width
        self.theta = start_theta(task.name, traits)
        self.start_theta = self.theta.copy()
        self.bounds = (
            np.maximum(np.asarray(self.space.low), self.theta - traits.reach * width),
            np.minimum(np.asarray(self.space.high), self.theta + traits.reach * width),
        )
        self.motor = Style(speed=traits.speed, gain=traits.gain, noise=0.0)
        self.memory: collections.deque[Shown] = collections.deque(maxlen=traits.memory)
        self.episodes_done = 0
        self.trial: dict[str, Any] | None = None
        self.log: list[dict[str, Any]] = []
        self.prompt_seen = False
        self._seen: Seen | None = None
        self._inner: Any = None
        self._history: list[np.ndarray] = []
        self._rng = np.random.default_rng(0)
        self._base_rows: dict[int, tuple[int, int]] | None = None

    @property
    def choices(self) -> dict[str, Any]:
        """The operator choices its current θ maps to."""
        return self.space.choices(self.theta)

    @property
    def start_choices(self) -> dict[str, Any]:
        return self.space.choices(self.start_theta)

    # --- acting ------------------------------------------------------------------------------
    def episode_style(self) -> Style:
        """The style it acts with now: its θ, its motor traits, noise lowered by practice."""
        noise = self.traits.noise_at(self.episodes_done)
        return dataclasses.replace(self.motor, noise=noise, choices=tuple(self.choices.items()))

    def restart(self, obs: np.ndarray) -> None:
        """Start its phases again from state ``obs (O,)`` (an HG-DAgger takeover)."""
        self._history = []
        self._inner.reset(np.asarray(obs, np.float64)[None], self._rng)

    def act(self, observation: Observation) -> np.ndarray:
        if self._inner is None or self._seen is None:
            raise ElicitError("the simulated person was asked to act before an episode started")
        self._history.append(np.asarray(observation.obs, np.float64))
        late = self._history[max(len(self._history) - 1 - self.traits.delay, 0)]
        return self._inner.act(late[None])[0]

    def on_event(self, event: Event) -> None:
        from elicit_jax.sim.operators import make_operator

        if isinstance(event, PromptEvent):
            self.learn_from_prompt(event)
        elif isinstance(event, EpisodeStartEvent):
            self.digest()
            self._rng = np.random.default_rng(event.operator_seed)
            self._inner = make_operator(self.task, self.name, style=self.episode_style())
            self._inner.reset(np.asarray(event.obs, np.float64)[None], self._rng)
            self._history = []
            self._seen = Seen(event.episode, event.episode_kind, indicator=event.indicator)
        elif isinstance(event, IndicatorEvent) and self._seen is not None:
            self._seen.red[event.step] = bool(event.incompatible)
            self._seen.allowed = float(event.allowed)
        elif isinstance(event, EpisodeEndEvent) and self._seen is not None:
            self._seen.success = bool(event.success)
        elif isinstance(event, ReviewEvent) and self._seen is not None:
            self._seen.feedback = tuple(event.feedback)
        elif isinstance(event, SessionEndEvent):
            self.digest(last=True)

    # --- learning from what was shown ----------------------------------------------------------
    def _set(self, episode: int, source: str, theta: np.ndarray, **extra: Any) -> None:
        old = self.space.named(self.theta)
        self.theta = self.space.clip(theta, *self.bounds)
        self.log.append(
            {"episode": episode, "source": source, "from": old,
             "to": self.space.named(self.theta), **extra}
        )  # fmt: skip

    def fit(self, episode: int, source: str) -> bool:
        """Fit θ to the remembered segments; adopt the fit (with a slip) if clearly better."""
        if not self.memory:
            return False
        rng = np.random.default_rng([self.traits.seed, episode, 23])
        best, now, after = fit_theta(
            self.task, self.motor, self.space, self.theta, self.bounds, list(self.memory),
            first_step=float(rng.uniform(0.5, 1.0)),
        )  # fmt: skip
        if now <= ERROR_FLOOR or after >= (1.0 - MIN_GAIN) * now:
            return False
        slipped = best + rng.normal(0.0, self.traits.slip * self.space.width)
        self.trial = None
        self._set(episode, source, slipped, error_before=now, error_after=after)
        return True

    def learn_from_prompt(self, event: PromptEvent) -> None:
        """Watch the prompt's demonstrations (once: a repeated prompt teaches nothing new)."""
        if self.prompt_seen or not event.episodes:
            return
        self.prompt_seen = True
        for e in event.episodes:
            self.memory.append(Shown(np.asarray(e.obs, np.float64), np.asarray(e.action, float)))
        rng = np.random.default_rng([self.traits.seed, 1_000_003])
        if rng.random() < self.traits.imitation:
            self.fit(self._seen.index + 1 if self._seen is not None else 0, "prompt")

    def digest(self, last: bool = False) -> None:
        """Think over the episode just finished (called when the next one starts, and with
        ``last`` when the session ends: no new practice trial then, as no episode would try
        it, so the final θ a session records is one the person acted with or fitted)."""
        seen, self._seen = self._seen, None
        if seen is None:
            return
        self.episodes_done += 1
        rng = np.random.default_rng([self.traits.seed, seen.index, 17])
        changed = self.trial is not None  # a trial just judged: no new one this time
        if self.trial is not None:
            self._settle_trial(seen)
        if seen.kind == DEMONSTRATION and seen.feedback:
            changed = self._learn_from_feedback(seen, rng) or changed
        if last or changed or self.trial is not None or not seen.bad:
            return
        if rng.random() < self.traits.explore:
            step = rng.normal(0.0, TRIAL_STEP * self.space.width)
            self.trial = {"old": self.theta.copy(), "red_before": seen.red_fraction}
            self._set(seen.index, "practice-try", self.theta + step, success=seen.success,
                      red=seen.red_fraction)  # fmt: skip

    def _settle_trial(self, seen: Seen) -> None:
        trial, self.trial = self.trial, None
        assert trial is not None
        better = seen.success and (
            not seen.indicator
            or seen.red_fraction < (1.0 - MIN_GAIN) * trial["red_before"]
            or not seen.bad
        )
        detail = {"success": seen.success, "red": seen.red_fraction}
        if better:
            self.log.append({"episode": seen.index, "source": "practice-keep",
                             "from": self.space.named(self.theta),
                             "to": self.space.named(self.theta), **detail})  # fmt: skip
        else:
            self._set(seen.index, "practice-undo", trial["old"], **detail)

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

        watched = False
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
            self.memory.append(Shown(states, actions, span, weights, "feedback"))
            watched = True
        return self.fit(seen.index, "feedback") if watched else False

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
        """JSON-ready: who it is, its starting and current θ and choices, every change."""
        return to_jsonable(
            {
                "person": self.traits.spec(),
                "traits": dataclasses.asdict(self.traits),
                "parameters": list(self.space.names),
                "bounds": [self.space.named(self.bounds[0]), self.space.named(self.bounds[1])],
                "start_theta": self.space.named(self.start_theta),
                "theta": self.space.named(self.theta),
                "start_choices": self.start_choices,
                "choices": self.choices,
                "episodes_done": self.episodes_done,
                "changes": self.log,
            }
        )


def start_theta(task_name: str, traits: PersonTraits) -> np.ndarray:
    """A person's starting θ: its space's prior restricted to what its starting style's
    choices pin down (:meth:`~elicit_jax.elicit.people.space.ParamSpace.start`, seeded by the
    person), or the space's stated compatible θ for :data:`COMPATIBLE_STYLE`. It reads the
    starting style's entry only: never the base operator's, nor the list of styles.

    Raises:
      ElicitError: the base operator's style, or a style the task does not have.
    """
    from elicit_jax.sim.operators import style_of

    if traits.style == BASE_STYLE:
        raise ElicitError(
            "a simulated person cannot start from the base operator's style "
            f"(start from {COMPATIBLE_STYLE} for a compatible person)"
        )
    space = space_of(task_name)
    if traits.style == COMPATIBLE_STYLE:
        return space.clip(np.array(space.compatible, np.float64))
    rng = np.random.default_rng([traits.seed, 31])
    return space.start(style_of(task_name, traits.style).choices, rng)


def seen_from_record(rec: Any, config: Any, rule: Any) -> Seen:
    """What the person saw of a recorded episode (for :meth:`SimulatedPerson.catch_up`)."""
    indicator = rec.kind == DEMONSTRATION and config.shown("indicator")
    seen = Seen(rec.index, rec.kind, indicator=indicator, success=bool(rec.success))
    if indicator:
        scored = np.flatnonzero(rec.scored)
        seen.red = {int(t): bool(rec.incompatible[t]) for t in scored}
        seen.allowed = float(rule.allowed(len(scored)))
    if rec.feedback_shown and rec.verdict == "rejected":
        seen.feedback = tuple(rec.feedback)
    return seen
