"""The browser as a session operator: ``browser:NAME`` holds the page's latest command.

A web page cannot answer ``act(observation)`` synchronously, so the browser's operator keeps
the latest command the page sent (an action vector and, in HG-DAgger, whether the operator
has taken over) and answers every ``act`` with it; the server's driver calls ``act`` once a
control step, at the task's rate. Events go to a listener the driver installs.

Importing this module registers the ``browser`` operator kind
(:func:`~elicit_jax.elicit.operators.register_operator`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from elicit_jax.elicit.events import Event, Observation
from elicit_jax.elicit.operators import OperatorContext, register_operator

KIND = "browser"


def neutral_action(action_names: tuple[str, ...]) -> np.ndarray:
    """(A,) the command of an idle operator: no motion, gripper open."""
    a = np.zeros(len(action_names), np.float32)
    if "gripper" in action_names:
        a[action_names.index("gripper")] = -1.0
    return a


class BrowserOperator:
    """The latest command of one browser (thread-safe: the page writes, the driver reads).

    Attributes:
      name: the operator's name (their session directory).
      listener: called with every session event (set by the driver).
    """

    def __init__(self, name: str, action_names: tuple[str, ...], dagger: bool) -> None:
        self.name = name
        self.listener: Callable[[Event], None] | None = None
        self._neutral = neutral_action(action_names)
        self._lock = threading.Lock()
        self._action = self._neutral.copy()
        self._in_control = not dagger

    def set_action(self, action: Any) -> None:
        """The page's current command ``(A,)``."""
        with self._lock:
            self._action = np.asarray(action, np.float32).copy()

    def set_control(self, operator: bool) -> None:
        """HG-DAgger: the operator takes over (True) or hands back to the robot (False)."""
        with self._lock:
            self._in_control = bool(operator)

    @property
    def in_control(self) -> bool:
        with self._lock:
            return self._in_control

    def reset(self, dagger: bool) -> None:
        """Back to the idle command (a new episode); in DAgger the robot acts first."""
        with self._lock:
            self._action = self._neutral.copy()
            self._in_control = not dagger

    def act(self, observation: Observation) -> np.ndarray | None:
        with self._lock:
            if observation.dagger and not self._in_control:
                return None
            return self._action.copy()

    def on_event(self, event: Event) -> None:
        if self.listener is not None:
            self.listener(event)


def _browser(name: str, context: OperatorContext) -> BrowserOperator:
    from elicit_jax.elicit.inputs import task_action_names

    return BrowserOperator(name, task_action_names(context.task), context.dagger)


register_operator(KIND, _browser)
