"""The session state machine: practice → prompt → demonstrate (live M) → review → … → done.

A :class:`Session` is driven one control step at a time, by whoever owns the loop:

    session.start()                        # resumes from the episode files, emits events
    while not session.done:
        session.step(operator.act(session.observation()))

(:func:`elicit_jax.elicit.run.run_session` is exactly this loop for a synchronous operator;
a web server calls the same methods from its own loop.) Everything else — ending an
episode, judging it, writing it, feedback, retraining, starting the next — happens inside
:meth:`Session.step` when an episode ends, and is announced through the listeners as events
(:mod:`elicit_jax.elicit.events`). A caller that must show the episode's last state before
that work (a web page's last frame) steps with ``finish=False`` and calls
:meth:`Session.finish_episode` once it has: the result is the same.

Phases: ``practice`` (``config.practice`` episodes, recorded, never demonstrations) →
``prompt`` (informed mode: the ``config.prompt`` base demonstrations the base policy fits
best — lowest mean likelihood error ℓ, ties to the lower episode id) → ``demonstrate`` (one
episode; each of the operator's steps is scored live; informed mode shows the indicator) →
``review`` (the accept/reject rule; informed mode shows the verdict and, on a rejection, the
feedback; naive mode accepts every demonstration that completes the task and only records
the rule's verdict) → ``retrain`` after each ``config.batch`` accepted demonstrations →
``demonstrate`` … → ``done`` when ``config.demos`` are accepted or ``config.episode_limit``
episodes are recorded.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from elicit_jax.elicit.events import (
    DEMONSTRATION,
    PRACTICE,
    EpisodeEndEvent,
    EpisodeStartEvent,
    Event,
    IndicatorEvent,
    Observation,
    PhaseEvent,
    ReviewEvent,
    SessionEndEvent,
)
from elicit_jax.elicit.light import is_idle, live_state
from elicit_jax.elicit.progress import Progress, operator_seed
from elicit_jax.elicit.store import EpisodeRecord
from elicit_jax.errors import ElicitError

Listener = Callable[[Event], None]


class Session:
    """One elicitation session over a :class:`~elicit_jax.elicit.setup.SessionSetup`.

    Attributes:
      setup: resources (config, task, policies, scorer, store).
      progress: counts and accepted demonstrations, recomputed from the episode files.
      phase: current protocol phase.
      done: the session is over.
    """

    def __init__(self, setup: Any, listeners: list[Listener] | None = None) -> None:
        self.setup = setup
        self.config = setup.config
        self.listeners = list(listeners or [])
        self.progress = Progress.load(setup.store, setup.config)
        self.phase = ""
        self.done = False
        self.end_reason = ""
        self._sim: Any = None
        self._buf: dict[str, list[Any]] = {}
        self._robot_action: tuple[int, np.ndarray] | None = None
        self._prompted = False
        self._ended: bool | None = None

    # --- public driving API ----------------------------------------------------------------
    def start(self) -> None:
        """Train any batch policy a crash left missing, then begin the next episode."""
        self.setup.catch_up_policies(self.progress, self._emit)
        self._next_episode()

    def observation(self) -> Observation:
        """What the operator sees at the current step."""
        self._require_running()
        obs = self._sim.obs[0].astype(np.float32)
        policy_action = None
        if self.config.dagger:
            policy_action = self._policy_action(obs)
        return Observation(
            obs=obs,
            step=len(self._buf["obs"]),
            episode=self._index,
            kind=self._kind,
            dagger=self.config.dagger,
            policy_action=policy_action,
            operator_in_control=bool(self._buf["operator"] and self._buf["operator"][-1]),
        )

    def step(self, action: np.ndarray | None, finish: bool = True) -> None:
        """Apply one control step (``None``: the robot's action, DAgger only).

        Args:
          action: (A,) the operator's action, or None.
          finish: when this step ends the episode, judge and write it now (and begin the next
            one). With False the episode is left :attr:`episode_over` — its last state still
            in :attr:`sim_data` — until :meth:`finish_episode` is called.
        """
        self._require_running()
        t0 = time.perf_counter()
        obs = self._sim.obs[0].astype(np.float32)
        by_operator = action is not None
        if action is None:
            if not self.config.dagger:
                raise ElicitError(
                    f"operator '{self.config.operator}' gave no action in a {self._kind} "
                    "episode (only HG-DAgger episodes let the robot act)"
                )
            applied = self._policy_action(obs)
        else:
            applied = self._check_action(action)
        buf = self._buf
        d = self._sim.datas[0]
        buf["qpos"].append(d.qpos.copy())
        buf["qvel"].append(d.qvel.copy())
        buf["time_s"].append(t0 - self._t0)
        buf["obs"].append(obs)
        buf["action"].append(applied)
        buf["operator"].append(by_operator)
        if by_operator:
            self._score(obs, applied, buf["action"][-2] if len(buf["action"]) > 1 else None)
        else:
            buf["score"].append((np.nan, np.nan, np.nan, False, np.nan))
        self._sim.step(applied[None].astype(np.float64))
        length = len(buf["obs"])
        if self._sim.success[0]:
            self._ended = True
        elif self._sim.unstable[0] or length >= self.setup.task.config.horizon:
            self._ended = False
        if finish:
            self.finish_episode()

    @property
    def episode_over(self) -> bool:
        """The current episode has ended and waits for :meth:`finish_episode`."""
        return self._ended is not None

    def finish_episode(self) -> None:
        """Judge and write the episode that ended (``step(..., finish=False)``), announce it,
        and begin the next one; nothing happens while no episode has ended."""
        if self._ended is not None:
            success, self._ended = self._ended, None
            self._finish(success)

    def end_episode(self) -> None:
        """End the current episode now (the operator gives up); it counts as not solved."""
        self._require_running()
        self._finish(success=False, gave_up=True)

    @property
    def sim_data(self) -> Any:
        """The current episode's MuJoCo ``MjData`` (to read, e.g. body poses to draw; never
        write it), or None before :meth:`start` and after the session ends. For a robosuite
        task it is the robosuite environment's own data."""
        return None if self._sim is None else self._sim.datas[0]

    def add_listener(self, listener: Listener) -> None:
        self.listeners.append(listener)

    def close(self) -> None:
        """Release the simulator."""
        if self._sim is not None:
            self._sim.close()
            self._sim = None

    # --- internals ---------------------------------------------------------------------------
    def _emit(self, event: Event) -> None:
        for fn in self.listeners:
            fn(event)

    def _set_phase(self, phase: str, message: str) -> None:
        if phase != self.phase:
            self.phase = phase
            self._emit(PhaseEvent(phase, message, self.progress.counts))

    def _require_running(self) -> None:
        if self.done:
            raise ElicitError("the session is over")
        if self._sim is None:
            raise ElicitError("the session has not started (call start())")
        if self._ended is not None:
            raise ElicitError("the episode has ended (call finish_episode())")

    def _check_action(self, action: Any) -> np.ndarray:
        a = np.asarray(action, np.float64)
        dim = self.setup.action_dim
        if a.shape != (dim,):
            raise ElicitError(
                f"operator '{self.config.operator}' gave an action of shape {a.shape}, "
                f"expected ({dim},)"
            )
        if not np.isfinite(a).all():
            raise ElicitError(f"operator '{self.config.operator}' gave a non-finite action")
        return np.clip(a, -1.0, 1.0).astype(np.float32)

    def _policy_action(self, obs: np.ndarray) -> np.ndarray:
        """The current policy's action at this step's state (computed once per step)."""
        step = len(self._buf["obs"])
        if self._robot_action is None or self._robot_action[0] != step:
            zeros = np.zeros(self.setup.action_dim, np.float32)
            a = self.setup.scorer.score(self.setup.policy.policy, obs, zeros).policy_action
            self._robot_action = (step, a.astype(np.float32))
        return self._robot_action[1]

    def _score(self, obs: np.ndarray, action: np.ndarray, previous: np.ndarray | None) -> None:
        t = time.perf_counter()
        step = len(self._buf["obs"]) - 1
        s = self.setup.scorer.score(self.setup.policy.policy, obs, action, step=step)
        ms = 1e3 * (time.perf_counter() - t)
        buf = self._buf
        buf["score"].append((s.likelihood, s.novelty, s.compatibility, s.incompatible, ms))
        self._n_scored += 1
        self._n_incompatible += int(s.incompatible)
        if self._indicator:
            eta = self.setup.scorer.config.thresholds.eta
            live = live_state(
                self.setup.rule,
                int(self.setup.task.config.horizon),
                self._n_incompatible,
                self._n_scored,
                incompatible=s.incompatible,
                unfamiliar=bool(np.float32(s.novelty) >= np.float32(eta)),
                idle=is_idle(action, previous, self.setup.action_names),
            )
            self._emit(
                IndicatorEvent(
                    step=len(buf["obs"]) - 1,
                    likelihood=s.likelihood,
                    novelty=s.novelty,
                    compatibility=s.compatibility,
                    incompatible=s.incompatible,
                    incompatible_so_far=self._n_incompatible,
                    allowed=self.setup.rule.allowed(self._n_scored),
                    live=live,
                )
            )

    def _next_episode(self) -> None:
        c, counts = self.config, self.progress.counts
        if counts.accepted >= c.demos:
            return self._end("complete")
        if counts.episodes >= c.episode_limit:
            return self._end("max-episodes")
        kind = PRACTICE if counts.practice < c.practice else DEMONSTRATION
        if kind == PRACTICE:
            self._set_phase(PRACTICE, f"practice {counts.practice + 1} of {c.practice}")
        else:
            if c.shown("prompt") and c.prompt and not self._prompted:
                self._set_phase("prompt", f"watch {c.prompt} demonstrations of the base operator")
                self._emit(self.setup.prompt_event())
                self._prompted = True
            self._set_phase(
                "demonstrate", f"demonstration {counts.accepted + 1} of {c.demos} wanted"
            )
        self._begin(kind)

    def _begin(self, kind: str) -> None:
        from elicit_jax.sim.single import open_env

        if self._sim is None:  # C MuJoCo, or a robosuite environment in this process
            self._sim = open_env(self.setup.task)
        self._index = self.progress.next_index
        self._kind = kind
        self._indicator = kind == DEMONSTRATION and self.config.shown("indicator")
        self._init_seed = self.config.init_seed(self._index)
        self._sim.reset_seeds(np.array([self._init_seed]))
        self._buf = {
            k: [] for k in ("obs", "action", "operator", "qpos", "qvel", "time_s", "score")
        }
        self._n_scored = self._n_incompatible = 0
        self._robot_action = None
        self._t0 = time.perf_counter()
        self._started = time.time()
        self._emit(
            EpisodeStartEvent(
                episode=self._index,
                episode_kind=kind,
                obs=self._sim.obs[0].astype(np.float32),
                init_seed=self._init_seed,
                operator_seed=operator_seed(self.config, self._index),
                horizon=int(self.setup.task.config.horizon),
                dagger=self.config.dagger,
                indicator=self._indicator,
            )
        )
        if self._sim.success[0]:  # solved at reset: nothing to demonstrate
            self._finish(success=True)

    def _finish(self, success: bool, gave_up: bool = False) -> None:
        rec = self.setup.judge(self._record(success, gave_up), self.progress)
        self.setup.store.write_episode(rec, {"config": self.config.to_dict()})
        self.progress = self.progress.add(rec)
        if rec.verdict == "accepted":
            self.setup.write_demos(self.progress)
        counts = self.progress.counts
        self._emit(
            EpisodeEndEvent(
                episode=rec.index,
                episode_kind=rec.kind,
                success=rec.success,
                length=rec.length,
                operator_steps=int(np.sum(rec.operator)),
                counted=rec.verdict == "accepted",
                counts=counts,
                gave_up=gave_up,
            )
        )
        if rec.feedback_shown:
            self._set_phase("review", rec.text)
            self._emit(
                ReviewEvent(
                    episode=rec.index,
                    verdict=rec.verdict,
                    incompatible=rec.n_incompatible,
                    scored=rec.n_scored,
                    fraction=rec.n_incompatible / max(rec.n_scored, 1),
                    rule=self.setup.rule.describe(),
                    feedback=rec.feedback if rec.verdict == "rejected" else (),
                    text=rec.text,
                )
            )
        self.setup.write_manifest(self.progress)
        if rec.verdict == "accepted":
            self._retrain_if_due()
        self._next_episode()

    def _retrain_if_due(self) -> None:
        b = self.config.batch
        if not b or self.progress.counts.accepted % b:
            return
        self._set_phase("retrain", f"training on the first {self.progress.counts.accepted} demos")
        self.setup.catch_up_policies(self.progress, self._emit)

    def _record(self, success: bool, gave_up: bool = False) -> EpisodeRecord:
        buf = self._buf
        n, dim_o, dim_a = len(buf["obs"]), self.setup.obs_dim, self.setup.action_dim
        score = np.array(buf["score"], np.float64).reshape(n, 5)
        nq, nv = self._sim.model.nq, self._sim.model.nv
        return EpisodeRecord(
            index=self._index,
            kind=self._kind,
            init_seed=self._init_seed,
            operator_seed=operator_seed(self.config, self._index),
            batch=0,
            policy_batch=self.setup.policy_batch,
            success=bool(success),
            verdict="",
            rule_verdict="",
            feedback=(),
            feedback_shown=False,
            text="",
            obs=np.array(buf["obs"], np.float32).reshape(n, dim_o),
            action=np.array(buf["action"], np.float32).reshape(n, dim_a),
            qpos=np.array(buf["qpos"], np.float64).reshape(n, nq),
            qvel=np.array(buf["qvel"], np.float64).reshape(n, nv),
            operator=np.array(buf["operator"], bool).reshape(n),
            likelihood=score[:, 0],
            novelty=score[:, 1],
            compatibility=score[:, 2],
            incompatible=np.nan_to_num(score[:, 3]).astype(bool),
            time_s=np.array(buf["time_s"], np.float64).reshape(n),
            score_ms=score[:, 4],
            meta={
                "started": self._started,
                "seconds": time.perf_counter() - self._t0,
                "unstable": bool(self._sim.unstable[0]),
                "gave_up": gave_up,
                **self.config.thresholds.to_json(),
            },
        )

    def _end(self, reason: str) -> None:
        self.done = True
        self.end_reason = reason
        self.close()
        self._set_phase("done", f"session over: {reason}")
        self._emit(SessionEndEvent(reason, self.progress.counts))
