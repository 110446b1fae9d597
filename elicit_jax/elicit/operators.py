"""Operators behind the session interface: a registry, scripted operators, a scripted intervener.

Operators are named ``KIND:NAME``. Built in:

* ``scripted:STYLE`` — a scripted operator of the task (``elicit-jax tasks`` lists the
  styles), wrapped by :class:`ScriptedOperator`. Scripted operators do not learn: they ignore
  prompts, indicators and feedback, so an informed session with a conflicting style is
  rejected demonstration after demonstration (until ``--max-episodes``). In an HG-DAgger
  session the same operator is wrapped by :class:`ScriptedIntervener`.

Other kinds (the simulated people of a study, a browser) register a factory with
:func:`register_operator`; a factory takes the NAME after the colon and an
:class:`OperatorContext` and returns a :class:`~elicit_jax.elicit.events.SessionOperator`.

**The scripted intervener** (HG-DAgger, documented rule). While the robot acts, the
intervener watches two signs of trouble and takes over at the first:

1. *no progress*: the end effector (``robot0_eef_pos``) moved less than ``stall_distance``
   (1 cm) over the last ``stall_steps`` (20) robot-controlled steps;
2. *off the base's route*: the state is further than ``route_distance`` (5) from every
   state of the base demonstrations, in Euclidean distance of base-normalised states (each
   dimension in units of the base data's standard deviation). Measured on square-nut with
   10 base demonstrations: new same-style episodes stay below 4.5, a weak policy's states
   reach 4–7.

On taking over it restarts its scripted operator from the current state (the operator's
phases start again from the first and follow the state from there) and keeps control for at
least ``hold_steps`` (30) steps; it then hands control back as soon as the state is on the
base's route again. Only the steps it controls are the session's demonstration.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from elicit_jax.compat.feedback import normalizer
from elicit_jax.elicit.events import EpisodeStartEvent, Event, Observation, SessionOperator
from elicit_jax.errors import ElicitError


@dataclasses.dataclass(frozen=True)
class OperatorContext:
    """What an operator factory may use.

    Attributes:
      task: the simulated task (``elicit_jax.sim.env.Task``).
      base: the base demonstrations (``Demos``).
      dagger: the session is HG-DAgger.
    """

    task: Any
    base: Any
    dagger: bool = False


Factory = Callable[[str, OperatorContext], SessionOperator]
_FACTORIES: dict[str, Factory] = {}


def register_operator(kind: str, factory: Factory) -> None:
    """Make ``KIND:NAME`` operators available to sessions."""
    _FACTORIES[kind] = factory


def operator_kinds() -> list[str]:
    """Registered operator kinds."""
    return sorted(_FACTORIES)


def make_session_operator(spec: str, context: OperatorContext) -> SessionOperator:
    """The operator named ``spec`` (``KIND:NAME``).

    Raises:
      ElicitError: malformed spec, unknown kind or name.
    """
    kind, sep, name = spec.partition(":")
    if not sep or not name:
        raise ElicitError(f"operator must look like KIND:NAME (e.g. scripted:base), got {spec!r}")
    if kind not in _FACTORIES:
        raise ElicitError(
            f"unknown operator kind '{kind}' in {spec!r} (known: {', '.join(operator_kinds())})"
        )
    return _FACTORIES[kind](name, context)


class ScriptedOperator:
    """A scripted operator of :mod:`elicit_jax.sim.operators`, one environment at a time.

    Each episode it restarts from the first state with a random generator seeded by the
    episode's ``operator_seed`` (so a resumed session repeats it exactly).
    """

    def __init__(self, task: Any, style: str) -> None:
        from elicit_jax.sim.operators import make_operator

        self.inner = make_operator(task, style)
        self.name = style
        self.rng = np.random.default_rng(0)

    def on_event(self, event: Event) -> None:
        if isinstance(event, EpisodeStartEvent):
            self.rng = np.random.default_rng(event.operator_seed)
            self.restart(event.obs)

    def restart(self, obs: np.ndarray) -> None:
        """Start the operator's phases again from state ``obs (O,)``."""
        self.inner.reset(np.asarray(obs, np.float64)[None], self.rng)

    def act(self, observation: Observation) -> np.ndarray:
        return self.inner.act(np.asarray(observation.obs, np.float64)[None])[0]


@dataclasses.dataclass(frozen=True)
class InterventionRule:
    """When the scripted intervener takes over and hands back (see the module docstring)."""

    stall_steps: int = 20
    stall_distance: float = 0.01
    route_distance: float = 5.0
    hold_steps: int = 30


class RouteDistance:
    """Euclidean distance of a state to the nearest base state, dims in base-std units."""

    def __init__(self, base_obs: np.ndarray) -> None:
        self.mean, self.std = normalizer(base_obs)
        self.points = ((np.asarray(base_obs, np.float64) - self.mean) / self.std).astype(np.float32)
        self.sq = np.sum(self.points.astype(np.float64) ** 2, axis=1)

    def __call__(self, obs: np.ndarray) -> float:
        x = (np.asarray(obs, np.float64) - self.mean) / self.std
        d2 = self.sq - 2.0 * (self.points @ x.astype(np.float32)) + float(x @ x)
        return float(np.sqrt(max(float(d2.min()), 0.0)))


class ScriptedIntervener:
    """HG-DAgger with a scripted operator: takes over on no progress or off route, hands back
    when on route again (see the module docstring)."""

    def __init__(
        self,
        operator: Any,
        base: Any,
        eef: slice,
        rule: InterventionRule = InterventionRule(),
    ) -> None:
        self.operator = operator
        self.name = operator.name
        self.rule = rule
        self.eef = eef
        self.route = RouteDistance(base.obs)
        self._reset()

    def _reset(self) -> None:
        self.in_control = False
        self.held = 0
        self.history: list[np.ndarray] = []

    def on_event(self, event: Event) -> None:
        self.operator.on_event(event)  # a learning operator hears everything
        if isinstance(event, EpisodeStartEvent):
            self._reset()

    def catch_up(self, setup: Any) -> None:
        """Let a learning operator relive a resumed session's finished episodes."""
        catch_up = getattr(self.operator, "catch_up", None)
        if catch_up is not None:
            catch_up(setup)

    def trouble(self, obs: np.ndarray) -> str:
        """``stalled``, ``off-route`` or ``""`` for the robot's current state."""
        r = self.rule
        self.history.append(np.asarray(obs[self.eef], np.float64))
        if len(self.history) > r.stall_steps:
            moved = np.linalg.norm(self.history[-1] - self.history[-1 - r.stall_steps])
            if moved < r.stall_distance:
                return "stalled"
        if self.route(obs) > r.route_distance:
            return "off-route"
        return ""

    def act(self, observation: Observation) -> np.ndarray | None:
        obs = np.asarray(observation.obs, np.float64)
        if not self.in_control:
            if not self.trouble(obs):
                return None
            self.operator.restart(obs)
            self.in_control, self.held = True, 0
        elif self.held >= self.rule.hold_steps and self.route(obs) <= self.rule.route_distance:
            self.in_control, self.history = False, [obs[self.eef]]
            return None
        self.held += 1
        return self.operator.act(observation)


def _eef_slice(task: Any) -> slice:
    for f in getattr(task, "obs_fields", ()):
        if f.name == "robot0_eef_pos":
            return slice(f.start, f.stop)
    return slice(0, 3)


def in_session(operator: Any, context: OperatorContext) -> SessionOperator:
    """``operator`` as it acts in a session of ``context``: wrapped by the
    :class:`ScriptedIntervener` in HG-DAgger (it needs ``restart(obs)`` and ``act``)."""
    if context.dagger:
        return ScriptedIntervener(operator, context.base, _eef_slice(context.task))
    return operator


def _scripted(name: str, context: OperatorContext) -> SessionOperator:
    return in_session(ScriptedOperator(context.task, name), context)


register_operator("scripted", _scripted)
