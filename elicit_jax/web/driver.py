"""One operator's session on its own thread, stepped at the task's control rate.

An :class:`OperatorDriver` owns a :class:`~elicit_jax.elicit.session.Session` (the physics —
C MuJoCo or a robosuite environment — and the live scorer run here, on the server) and drives
it from its thread, the way :func:`~elicit_jax.elicit.run.run_session` does but paced: one
control step per control period (50 ms on every shipped task), with the browser operator's
latest command. A command that changes (a key pressed or let go) pulls the next step forward
by up to half a period (:data:`EARLIEST`): the key's effect reaches the screen sooner, the
steps stay on their grid (the step after is due a period after the pulled one was due, so
an episode never runs faster than the control rate), and every step still simulates one
control period (the episode's steps and states are the same; only the wall-clock gaps
between its steps, ``time_s``, vary by up to half a period). Each step's pose frame is
sent before its indicator event. Each episode waits for the page's ``start`` (the operator
reads the instructions, the prompt or the feedback first); a lost connection pauses the
episode until the page is back. Everything the page needs to redraw itself after a
reload — the scene, the prompt, the current episode's indicator history and live state, a
pending verdict — is kept (:class:`~elicit_jax.web.page.PageFeed`), and sent again to
whichever connection attaches next (:meth:`OperatorDriver.attach`).
"""

from __future__ import annotations

import math
import threading
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.elicit.config import SessionConfig
from elicit_jax.elicit.events import (
    DEMONSTRATION,
    EpisodeEndEvent,
    EpisodeStartEvent,
    Event,
    IndicatorEvent,
    PhaseEvent,
    PromptEvent,
    RetrainEvent,
    ReviewEvent,
    SessionEndEvent,
    to_jsonable,
)
from elicit_jax.errors import ElicitError
from elicit_jax.web import messages
from elicit_jax.web.page import Outbox, PageFeed
from elicit_jax.web.protocol import Message, pack_frame
from elicit_jax.web.scene import body_poses, scene_origin

OPENING, READY, RUNNING, BUSY, DONE, ERROR = "opening", "ready", "running", "busy", "done", "error"
EARLIEST = 0.5
"""A new command pulls the next step forward by at most this fraction of a control period
(the key's effect is on screen sooner). The steps stay on their grid: the next one is due a
period after the one pulled was, so the episode never runs faster than the control rate."""


class OperatorDriver:
    """Runs the session of operator ``name`` in ``out`` (see the module docstring).

    Args:
      name: the operator's name.
      config: the session config (its operator is ``browser:NAME``).
      out: the session directory (created or resumed).
      log: where console lines go (the caller's: the CLI passes its echo).

    Attributes:
      state: ``opening``, ``ready`` (waiting for the page's start), ``running``, ``busy``
        (retraining), ``done`` or ``error``.
      message: why, for ``error``.
      steps: control steps taken (all episodes) since the server started.
      detached_at: when the last page went away (``time.monotonic()``).
    """

    def __init__(
        self, name: str, config: SessionConfig, out: Path, *, log: Callable[[str], None]
    ) -> None:
        self.name, self.config, self.out, self.log = name, config, Path(out), log
        self.state, self.message = OPENING, ""
        self.steps = 0
        self.detached_at = time.monotonic()
        self.session: Any = None
        self.setup: Any = None
        self.operator: Any = None
        self.period = 0.05
        self._lock = threading.RLock()
        self._wake = threading.Event()
        self._command = threading.Event()  # a new command: step soon
        self._stop = threading.Event()
        self._command_seen: Any = None
        self._page = PageFeed()
        self._go = self._give_up = False
        self._prompt_pending = self._review_pending = False
        self._index, self._kind, self._step = -1, "", 0
        self._m = math.nan
        self._clips: Any = None
        self._origin: Any = None
        self._thread = threading.Thread(target=self._run, name=f"operator-{name}", daemon=True)

    # --- control from the server -------------------------------------------------------------
    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop stepping (the episode in progress is not recorded) and release the simulator."""
        self._stop.set()
        self._wake.set()
        self._command.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    @property
    def attached(self) -> bool:
        """A page is attached."""
        return self._page.outbox is not None

    def attach(self, outbox: Outbox) -> Outbox | None:
        """Send everything the page needs to ``outbox`` and make it the operator's page.

        Returns:
          The page attached before (the caller closes it), or None.
        """
        with self._lock:
            old, self._page.outbox = self._page.outbox, outbox
            if old is not None and old is not outbox and self.state == RUNNING:
                self._go, self.state = False, READY  # another window: pause until it starts
            for msg in self._snapshot():
                outbox.send(msg)
        return old if old is not outbox else None

    def detach(self, outbox: Outbox) -> None:
        """The page went away: pause the episode until one attaches again."""
        with self._lock:
            if self._page.outbox is not outbox:
                return
            self._page.outbox = None
            self.detached_at = time.monotonic()
            if self.state == RUNNING:
                self._go = False
                self.state = READY

    def close_page(self, code: int, reason: str) -> None:
        """Close the attached page's connection with ``code`` and ``reason`` (if one is)."""
        with self._lock:
            close = getattr(self._page.outbox, "close", None)
        if close is not None:
            close(code, reason)

    def status(self) -> dict[str, Any]:
        """Where the operator stands, for the experimenter's dashboard."""
        with self._lock:
            s = self.session
            rows = [] if s is None else s.progress.rows
            return {
                "state": self.state,
                "message": self.message,
                "attached": self.attached,
                "phase": getattr(s, "phase", ""),
                "episode": self._index,
                "episode_kind": self._kind,
                "step": self._step,
                "prompt_pending": self._prompt_pending,
                "review_pending": self._review_pending,
                "counts": None if s is None else to_jsonable(s.progress.counts),
                "last_verdict": str(rows[-1].get("verdict", "")) if rows else "",
                "steps": self.steps,
            }

    def handle(self, msg: Message) -> None:
        """Apply one checked message of the page (actions, control, start, give up)."""
        op = self.operator
        if msg.type == "action" and op is not None:
            op.set_action(np.asarray(msg.action, np.float32))
            if msg.action != self._command_seen:
                self._command_seen = msg.action
                self._command.set()
        elif msg.type == "control" and op is not None:
            op.set_control(msg.operator)
            self._command.set()
        elif msg.type == "start":
            with self._lock:
                if self.state == READY:
                    self._go, self.state = True, RUNNING
                    self._review_pending = False
                    if self._kind == DEMONSTRATION:
                        self._prompt_pending = False
                    self._push_state()
            self._wake.set()
        elif msg.type == "give-up":
            with self._lock:
                if self.state in (READY, RUNNING) and self._step > 0:
                    self._give_up = True
                    self._go, self.state = True, RUNNING
            self._wake.set()

    # --- the thread ---------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._open()
            self._loop()
        except ElicitError as e:
            self._fail(str(e))
        except Exception as e:  # report any failure to the page and the console, keep serving
            self.log(traceback.format_exc())
            self._fail(f"{type(e).__name__}: {e}")
        finally:
            if self.session is not None:
                self.session.close()

    def _fail(self, message: str) -> None:
        with self._lock:
            self.state, self.message = ERROR, message
            self._go = False
            self._send(messages.error(message))
            self._push_state()
        self.log(f"operator {self.name}: {message}")

    def _open(self) -> None:
        from elicit_jax.elicit.session import Session
        from elicit_jax.elicit.setup import open_session
        from elicit_jax.sim.single import control_period
        from elicit_jax.web import operator as browser  # registers the ``browser`` kind
        from elicit_jax.web.clips import ClipMaker

        if self.config.operator.partition(":")[0] != browser.KIND:
            raise ElicitError(f"a browser session needs a '{browser.KIND}:NAME' operator")
        setup, operator, resumed = open_session(self.config, self.out, quiet=True)
        self.setup, self.operator = setup, operator
        task = setup.task
        self.period = control_period(task)
        self._origin = scene_origin(task)
        self._clips = ClipMaker(task, setup.base)
        operator.listener = self._on_event
        self.session = Session(setup, [operator.on_event])
        if not setup.demos_up_to_date(self.session.progress):
            setup.write_demos(self.session.progress)
        with self._lock:
            self._page.opened(
                [messages.welcome(self.name, setup, resumed, self.period), messages.scene(task)]
            )
        self.log(
            f"operator {self.name}: session {'resumed' if resumed else 'created'} in {self.out}"
        )
        self.session.start()
        with self._lock:
            if self.state == OPENING:
                self.state = READY
            self._push_state()

    def _loop(self) -> None:
        next_t: float | None = None
        while not self._stop.is_set():
            if self.session.done:
                with self._lock:
                    self.state = DONE
                    self._push_state()
                self._stop.wait()
                return
            if not self._go:
                next_t = None
                self._wake.wait(0.25)
                self._wake.clear()
                continue
            next_t = time.perf_counter() if next_t is None else next_t
            if self._wait_until(next_t) is None:
                return
            next_t = max(next_t + self.period, time.perf_counter() - self.period)
            self._command.clear()  # commands from here on are news to the next step
            self._tick()

    def _wait_until(self, due: float) -> float | None:
        """Sleep until the step ``due``; a new command pulls it forward to
        :data:`EARLIEST` of a period before ``due`` (or now, if that has passed). Returns
        the time the step was let go at, or None once stopped."""
        at = due
        while True:
            now = time.perf_counter()
            if at <= now:
                return None if self._stop.is_set() else at
            if self._command.wait(at - now):
                self._command.clear()
                if self._stop.is_set():
                    return None
                at = min(at, max(due - EARLIEST * self.period, now))

    def _tick(self) -> None:
        s = self.session
        if self._give_up:
            self._give_up = False
            s.end_episode()
        else:
            obs = s.observation()
            action = self.operator.act(obs)
            self._m = math.nan
            self._page.in_step = True
            try:
                s.step(action, finish=False)
            finally:
                self._page.in_step = False
            self.steps += 1
            self._step = obs.step + 1
            poses = body_poses(s.sim_data, self._origin)
            frame = pack_frame(poses, obs.episode, self._step, self._m, action is not None)
            with self._lock:  # the step's indicator goes after its pose, off the key's path
                self._page.send_frame(frame, droppable=not s.episode_over)
            s.finish_episode()  # after the last frame is out: judging and writing take a while
        if self._review_pending and not s.done:
            with self._lock:
                if self.state == RUNNING:
                    self.state = READY
                self._push_state()

    # --- events (on the driver thread) ----------------------------------------------------------
    def _on_event(self, event: Event) -> None:
        with self._lock:
            if isinstance(event, IndicatorEvent):
                self._m = event.compatibility
                self._page.indicator(event)
            elif isinstance(event, EpisodeStartEvent):
                self._on_episode_start(event)
            elif isinstance(event, EpisodeEndEvent):
                self._on_episode_end(event)
            elif isinstance(event, PromptEvent):
                self._prompt_pending = True
                self._page.prompt(event, self._clips)
            elif isinstance(event, ReviewEvent):
                record = self.setup.store.read_episode(event.episode)
                allowed = self.setup.rule.allowed(event.scored)
                self._page.review(event, record, allowed, self._clips)
            elif isinstance(event, PhaseEvent):
                self._page.phase(event)
            elif isinstance(event, RetrainEvent):
                self.state = BUSY if event.status == "start" else READY
                self._send(messages.event(event))
                self._push_state()
            elif isinstance(event, SessionEndEvent):
                self._send(messages.event(event))

    def _on_episode_start(self, event: EpisodeStartEvent) -> None:
        self._index, self._kind, self._step = event.episode, event.episode_kind, 0
        self._give_up = False
        self.operator.reset(self.config.dagger)
        frame = pack_frame(body_poses(self.session.sim_data, self._origin), event.episode, 0)
        self._page.episode_start(event, frame)

    def _on_episode_end(self, event: EpisodeEndEvent) -> None:
        self._go = False
        self._review_pending = True
        self._step = event.length
        self._page.episode_end(event)
        row = self.session.progress.rows[-1]
        c = event.counts
        self.log(
            f"operator {self.name}: e{event.episode:04d} {event.episode_kind} "
            f"{str(row.get('verdict', '')).upper()} in {event.length} steps "
            f"[{c.accepted}/{c.wanted} accepted, {c.episodes} episodes]"
        )

    # --- messages -----------------------------------------------------------------------------
    def _send(self, msg: str | bytes) -> None:
        self._page.send(msg)

    def _push_state(self) -> None:
        self._send(self._state_message())

    def _state_message(self) -> str:
        s = self.session
        progress = getattr(s, "progress", None)
        return messages.state(
            state=self.state,
            message=self.message,
            phase=getattr(s, "phase", ""),
            episode=getattr(self, "_index", -1),
            episode_kind=getattr(self, "_kind", ""),
            step=self._step,
            counts=None if progress is None else to_jsonable(progress.counts),
            history=[] if progress is None else messages.history(progress.rows),
            prompt_pending=self._prompt_pending,
            review_pending=self._review_pending,
            operator_control=bool(self.operator.in_control) if self.operator else False,
            steps_per_second=1.0 / self.period,
        )

    def _snapshot(self) -> list[str | bytes]:
        return self._page.snapshot(
            review_pending=self._review_pending,
            error=self.message if self.state == ERROR else None,
            state=self._state_message(),
        )
