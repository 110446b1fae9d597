"""The operator interface: what a session asks of whoever acts, and what it tells them.

A session (:mod:`elicit_jax.elicit.session`) talks to its operator through one seam, the
:class:`SessionOperator` protocol, with two methods:

* ``act(observation) -> action`` is called once per control step while an episode runs. The
  :class:`Observation` holds the state the operator sees; the answer is an action ``(A,)`` in
  the task's bounds (clipped to them), or ``None``. ``None`` means "leave control to the
  robot" and is only allowed in HG-DAgger episodes (``observation.dagger``): there the
  policy's own action (``observation.policy_action``) is applied and the step is not the
  operator's. Returning an action in a DAgger episode takes over control for that step.
* ``on_event(event)`` is called for everything else, with one of the immutable events below,
  in this order over a session: :class:`PhaseEvent` whenever the protocol's phase changes,
  :class:`PromptEvent` (informed mode: base demonstrations to watch before demonstrating),
  :class:`EpisodeStartEvent` at the start of every episode, :class:`IndicatorEvent` after every
  scored step of an informed demonstration (the live green/red indicator),
  :class:`EpisodeEndEvent` when an episode ends, :class:`ReviewEvent` after each informed
  demonstration (the verdict and, on a rejection, the feedback), :class:`RetrainEvent` around
  each retraining, and :class:`SessionEndEvent` last.

Scripted operators (:mod:`elicit_jax.elicit.operators`), the simulated people of a study, a
browser front end and a folder watcher all implement (or feed) this interface; none of them
needs to know how the session stores, scores or retrains. A session can also be driven from
outside (a web server's own loop): see :class:`~elicit_jax.elicit.session.Session`, whose
``observation()`` / ``step(action)`` pair is the same contract seen from the other side.

Every event converts to JSON-ready data with :func:`event_to_dict` (arrays become lists), the
form a transport layer sends over the wire.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from elicit_jax.elicit.light import LiveState

PRACTICE = "practice"
DEMONSTRATION = "demonstration"


@dataclasses.dataclass(frozen=True)
class Counts:
    """Progress of a session.

    Attributes:
      practice: practice episodes done.
      accepted: demonstrations accepted (they form the session's demos artifact).
      rejected: demonstrations rejected by the rule (informed mode).
      failed: demonstrations that did not complete the task (never accepted).
      unused: DAgger episodes the robot finished with no intervention (nothing to store).
      episodes: all episodes recorded, practice included.
      wanted: demonstrations the session wants accepted.
    """

    practice: int = 0
    accepted: int = 0
    rejected: int = 0
    failed: int = 0
    unused: int = 0
    episodes: int = 0
    wanted: int = 0


@dataclasses.dataclass(frozen=True)
class Observation:
    """What the operator sees at one control step.

    Attributes:
      obs: (O,) the state (observation vector of the task).
      step: control step within the episode, from 0.
      episode: the session's episode index (practice included), from 0.
      kind: ``practice`` or ``demonstration``.
      dagger: HG-DAgger episode: ``None`` leaves control to the robot.
      policy_action: (A,) the current policy's action at this state (DAgger only, else None).
      operator_in_control: DAgger: the operator controlled the previous step.
    """

    obs: np.ndarray
    step: int
    episode: int
    kind: str
    dagger: bool = False
    policy_action: np.ndarray | None = None
    operator_in_control: bool = False


@dataclasses.dataclass(frozen=True)
class PhaseEvent:
    """The protocol entered ``phase`` (practice, prompt, demonstrate, review, retrain, done)."""

    kind: ClassVar[str] = "phase"
    phase: str
    message: str
    counts: Counts


@dataclasses.dataclass(frozen=True)
class PromptEpisode:
    """One base demonstration shown in the prompt.

    Attributes:
      base_episode: its episode id in the base demonstrations.
      obs: (T, O) its states.
      action: (T, A) its actions.
      init_seed: the simulator seed of its initial state, when recorded (exact replay), or -1.
      mean_likelihood: mean ℓ of its pairs under the policy (why it was chosen: lowest first).
    """

    base_episode: int
    obs: np.ndarray
    action: np.ndarray
    init_seed: int
    mean_likelihood: float


@dataclasses.dataclass(frozen=True)
class PromptEvent:
    """Base demonstrations to watch before demonstrating (informed mode only)."""

    kind: ClassVar[str] = "prompt"
    episodes: tuple[PromptEpisode, ...]
    message: str


@dataclasses.dataclass(frozen=True)
class EpisodeStartEvent:
    """An episode starts.

    Attributes:
      episode: session episode index.
      episode_kind: ``practice`` or ``demonstration``.
      obs: (O,) the first state.
      init_seed: simulator seed of the initial state.
      operator_seed: seed for the operator's own randomness in this episode (scripted operators
        use it, so a resumed session repeats them exactly).
      horizon: control steps before the episode ends unsolved.
      dagger: HG-DAgger episode (the robot acts unless the operator takes over).
      indicator: live indicator events will follow each scored step.
    """

    kind: ClassVar[str] = "episode-start"
    episode: int
    episode_kind: str
    obs: np.ndarray
    init_seed: int
    operator_seed: int
    horizon: int
    dagger: bool
    indicator: bool


@dataclasses.dataclass(frozen=True)
class IndicatorEvent:
    """The live indicator after one scored step (green when compatible, red when not).

    Attributes:
      step: control step.
      likelihood: ℓ of the operator's action at this state.
      novelty: ν of the state.
      compatibility: M in [0, 1].
      incompatible: M == 0 (red).
      incompatible_so_far: incompatible pairs of this episode so far.
      allowed: most incompatible pairs the rule allows for the episode so far.
      live: the live state shown to the operator — the step's light (red, idle, unfamiliar,
        fits), the red steps allowed at the horizon, whether the episode can still be
        accepted and the verdict if it ended now (:mod:`elicit_jax.elicit.light`); it never
        contradicts the episode's verdict.
    """

    kind: ClassVar[str] = "indicator"
    step: int
    likelihood: float
    novelty: float
    compatibility: float
    incompatible: bool
    incompatible_so_far: int
    allowed: float
    live: LiveState | None = None


@dataclasses.dataclass(frozen=True)
class EpisodeEndEvent:
    """An episode ended.

    Attributes:
      episode: session episode index.
      episode_kind: ``practice`` or ``demonstration``.
      success: the task was completed.
      length: control steps.
      operator_steps: steps the operator controlled (all of them outside DAgger).
      counted: the episode was accepted into the session's demonstrations.
      counts: session progress after this episode.
      gave_up: the operator ended it before the horizon (give up), unsolved.
    """

    kind: ClassVar[str] = "episode-end"
    episode: int
    episode_kind: str
    success: bool
    length: int
    operator_steps: int
    counted: bool
    counts: Counts
    gave_up: bool = False


@dataclasses.dataclass(frozen=True)
class FieldDifference:
    """How much one observation field or action dimension differs from the base segment.

    Attributes:
      name: field name (``robot0_eef_quat``) or action dimension name (``dyaw``).
      part: ``obs`` or ``action``.
      difference: mean difference over the window in the field's own units (rotation angle
        in rad for a quaternion field; Euclidean norm for a vector field).
      normalized: the same in units of the base data's standard deviation (what ranks them).
      unit: ``rad`` for rotations, else empty.
    """

    name: str
    part: str
    difference: float
    normalized: float
    unit: str = ""


@dataclasses.dataclass(frozen=True)
class WindowFeedback:
    """Feedback on one flagged window of a demonstration.

    Attributes:
      start: first step of the window (of the scored steps: in DAgger, operator steps).
      stop: one past its last step.
      incompatibility: mean ``1 − M`` over the window.
      base_episode: episode id of the retrieved base demonstration.
      base_start: first step of the matching base segment.
      base_stop: one past its last step.
      distance: retrieval distance (normalised states; L2 or DTW cost per step).
      fields: observation fields that differ most, largest first.
      actions: action dimensions that differ most, largest first.
      operator_motion: the operator's gripper speed in the window (m per step) where the
        states follow the simulated tasks' layout; else the mean per-step change of the
        normalised state.
      base_motion: the same for the base segment.
      motion: ``still`` (you hold still where the base moves), ``moving`` (you move where the
        base holds still) or empty.
      text: one line saying all of the above.
      plain: what differs in plain words, from the geometry of the states
        (:mod:`elicit_jax.elicit.plain`), most specific first; what the operator reads.
    """

    start: int
    stop: int
    incompatibility: float
    base_episode: int
    base_start: int
    base_stop: int
    distance: float
    fields: tuple[FieldDifference, ...]
    actions: tuple[FieldDifference, ...]
    operator_motion: float
    base_motion: float
    motion: str
    text: str
    plain: tuple[str, ...] = ()


@dataclasses.dataclass(frozen=True)
class ReviewEvent:
    """The verdict on an informed demonstration, with feedback when it is rejected.

    Attributes:
      episode: session episode index.
      verdict: ``accepted``, ``rejected`` or ``failed`` (task not completed).
      incompatible: incompatible pairs among the scored steps.
      scored: scored steps (the operator's steps).
      fraction: incompatible / scored.
      rule: the accept/reject rule in words.
      feedback: one entry per flagged window, worst first (empty unless rejected).
      text: a one-line summary.
    """

    kind: ClassVar[str] = "review"
    episode: int
    verdict: str
    incompatible: int
    scored: int
    fraction: float
    rule: str
    feedback: tuple[WindowFeedback, ...]
    text: str


@dataclasses.dataclass(frozen=True)
class RetrainEvent:
    """Retraining between batches: ``status`` is ``start`` or ``done``.

    Attributes:
      batch: the batch just completed (1-based).
      demos: accepted demonstrations trained on (with all base demonstrations).
      policy: the new policy's run directory.
      status: ``start`` or ``done``.
      scoring: ``new`` when the next batch is scored against it, ``base`` with a fixed base.
    """

    kind: ClassVar[str] = "retrain"
    batch: int
    demos: int
    policy: str
    status: str
    scoring: str


@dataclasses.dataclass(frozen=True)
class SessionEndEvent:
    """The session is over: ``reason`` is ``complete`` or ``max-episodes``."""

    kind: ClassVar[str] = "session-end"
    reason: str
    counts: Counts


Event = (
    PhaseEvent
    | PromptEvent
    | EpisodeStartEvent
    | IndicatorEvent
    | EpisodeEndEvent
    | ReviewEvent
    | RetrainEvent
    | SessionEndEvent
)


@runtime_checkable
class SessionOperator(Protocol):
    """Whoever acts in a session (see the module docstring for the contract)."""

    name: str

    def act(self, observation: Observation) -> np.ndarray | None:
        """The action ``(A,)`` for this step, or ``None`` (DAgger: leave it to the robot)."""
        ...

    def on_event(self, event: Event) -> None:
        """Be told about a prompt, an indicator, a verdict and feedback, a phase change."""
        ...


def to_jsonable(value: Any) -> Any:
    """Dataclasses, arrays and numpy scalars as plain JSON-ready Python values."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    if isinstance(value, tuple | list):
        return [to_jsonable(v) for v in value]
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    return value


def event_to_dict(event: Event) -> dict[str, Any]:
    """An event as ``{"kind": ..., field: value, ...}`` with arrays as lists."""
    return {"kind": event.kind, **to_jsonable(event)}
