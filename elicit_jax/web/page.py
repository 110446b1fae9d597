"""The operator's page as its driver sees it: the connection messages go to, and everything the
page needs to redraw itself after a reload, kept as the messages that drew it.

A :class:`PageFeed` belongs to one :class:`~elicit_jax.web.driver.OperatorDriver` and is used
under the driver's lock. It turns the session's events into the page's messages and sends
them to the attached connection (if one is); it keeps the scene, the prompt, the phase, the
current episode's start, indicator history and latest pose frame, and a pending review, so
that :meth:`PageFeed.snapshot` can draw the page again on whichever connection attaches next.
An indicator that arrives while a control step is being simulated is held back until that
step's pose frame is out (:meth:`PageFeed.send_frame`): the frame first, off the key's path.
"""

from __future__ import annotations

from typing import Any, Protocol

from elicit_jax.elicit.events import (
    EpisodeEndEvent,
    EpisodeStartEvent,
    IndicatorEvent,
    PhaseEvent,
    PromptEvent,
    ReviewEvent,
)
from elicit_jax.web import messages


class Outbox(Protocol):
    """Where a driver's messages go (a WebSocket connection); ``send`` is thread-safe."""

    def send(self, message: str | bytes, droppable: bool = False) -> None: ...


class PageFeed:
    """The attached page's connection and what a reloaded page is sent again.

    Attributes:
      outbox: the attached page's connection, or None.
      in_step: a control step is being simulated (its indicator waits for its frame).
    """

    def __init__(self) -> None:
        self.outbox: Outbox | None = None
        self.in_step = False
        self._after_frame: list[str] = []
        self._static: list[str] = []
        self._prompt: list[str | bytes] = []
        self._phase: list[str] = []
        self._episode: list[str | bytes] = []
        self._indicators: list[list[float]] = []
        self._last_indicator: IndicatorEvent | None = None
        self._frame: bytes | None = None
        self._review: list[str | bytes] = []

    # --- sending ------------------------------------------------------------------------------
    def send(self, msg: str | bytes, droppable: bool = False) -> None:
        """Send ``msg`` to the attached page, if one is (``droppable``: a frame the connection
        may skip when it falls behind)."""
        if self.outbox is not None:
            self.outbox.send(msg, droppable)

    def sendall(self, msgs: list[str | bytes]) -> None:
        """Send ``msgs`` in order."""
        for m in msgs:
            self.send(m)

    def send_frame(self, frame: bytes, droppable: bool) -> None:
        """Keep and send a step's pose frame, then the indicator held back for it."""
        self._frame = frame
        self.send(frame, droppable=droppable)
        after, self._after_frame = self._after_frame, []
        for msg in after:
            self.send(msg)

    # --- what the session shows ---------------------------------------------------------------
    def opened(self, static: list[str]) -> None:
        """The session is open: keep and send what never changes (welcome, scene)."""
        self._static = static
        self.sendall(list(static))

    def indicator(self, event: IndicatorEvent) -> None:
        """Record a step's indicator and send it (after the step's frame, in a step)."""
        self._indicators.append(
            [
                event.step,
                event.compatibility,
                float(event.incompatible),
                event.live.light if event.live else "",
            ]
        )
        self._last_indicator = event
        if self.in_step:
            self._after_frame.append(messages.event(event))
        else:
            self.send(messages.event(event))

    def episode_start(self, event: EpisodeStartEvent, frame: bytes) -> None:
        """A new episode and its first pose frame; the last episode's indicators are gone."""
        self._indicators, self._last_indicator = [], None
        self._episode = [messages.event(event)]
        self._frame = frame
        self.sendall([self._episode[0], frame])

    def episode_end(self, event: EpisodeEndEvent) -> None:
        """The episode is over (its last frame went out before): the review begins."""
        self._review = [messages.event(event)]
        self.sendall(self._review)

    def prompt(self, event: PromptEvent, clips: Any) -> None:
        """The prompt and its clips (``clips``: a :class:`~elicit_jax.web.clips.ClipMaker`)."""
        self._prompt = [messages.prompt(event)]
        self._prompt += clips.prompt_clips(event)
        self.sendall(self._prompt)

    def review(self, event: ReviewEvent, record: Any, allowed: Any, clips: Any) -> None:
        """An episode's review: its record, what the rule allowed, and its clips."""
        review = [messages.review(event, record, allowed), *clips.review_clips(event, record)]
        self._review += review
        self.sendall(review)

    def phase(self, event: PhaseEvent) -> None:
        """The session's phase changed."""
        self._phase = [messages.event(event)]
        self.send(self._phase[0])

    def snapshot(self, *, review_pending: bool, error: str | None, state: str) -> list[str | bytes]:
        """Every message a page attaching now needs, in order.

        Args:
          review_pending: the last episode's review is still on screen.
          error: the driver's error message, if it failed.
          state: the driver's state message (last).
        """
        out: list[str | bytes] = [*self._static, *self._prompt, *self._phase, *self._episode]
        if self._indicators:
            out.append(messages.indicators(self._indicators, self._last_indicator))
        if self._frame is not None:
            out.append(self._frame)
        if review_pending:
            out += self._review
        if error is not None:
            out.append(messages.error(error))
        out.append(state)
        return out
