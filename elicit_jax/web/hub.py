"""All operators of one server: a driver per name, created on first contact, kept until exit.

Each operator's session lives in ``SESSIONS/<name>/``. A name seen for the first time since
the server started gets an :class:`~elicit_jax.web.driver.OperatorDriver`, which creates the
session or resumes the one in its directory — so after a server restart every operator
finds their session where they left it when their page reconnects. A driver whose session
failed to open is replaced on the next contact (the operator may retry); when the hub is
full, the driver of the operator who left longest ago is released (resumed from disk if
they come back).
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable
from pathlib import Path

from elicit_jax.elicit.config import SessionConfig
from elicit_jax.web import operator as browser_operator
from elicit_jax.web.driver import DONE, ERROR, READY, OperatorDriver


class HubFull(Exception):
    """No room for another operator."""


def session_names(root: Path) -> list[str]:
    """Names of the operator sessions already in ``root`` (their directories)."""
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if (p / "artifact.json").is_file())


class OperatorHub:
    """The drivers of a server.

    Args:
      template: the session config every operator gets (its operator is replaced by
        ``browser:NAME``).
      root: the sessions directory.
      max_operators: most operators held at once; when full, the operator whose page left
        longest ago is released to make room (their session stays on disk).
      log: where console lines go.
    """

    def __init__(
        self,
        template: SessionConfig,
        root: Path,
        max_operators: int = 16,
        log: Callable[[str], None] = print,
    ) -> None:
        self.template, self.root = template, Path(root)
        self.max_operators, self.log = max_operators, log
        self.drivers: dict[str, OperatorDriver] = {}
        self._lock = threading.Lock()
        from elicit_jax.elicit.setup import task_action_names
        from elicit_jax.sim.env import make_task

        self.action_dim = len(task_action_names(make_task(template.task)))

    def config_for(self, name: str) -> SessionConfig:
        """The session config of operator ``name``."""
        return dataclasses.replace(self.template, operator=f"{browser_operator.KIND}:{name}")

    def driver(self, name: str) -> OperatorDriver:
        """The running driver of ``name``, started now if there is none (or it failed).

        Raises:
          HubFull: ``max_operators`` drivers run already.
        """
        with self._lock:
            d = self.drivers.get(name)
            if d is not None and d.state != ERROR:
                return d
            live = [x for x in self.drivers.values() if x.state != ERROR]
            if len(live) >= self.max_operators:
                self._release_idle(live)
            d = OperatorDriver(name, self.config_for(name), self.root / name, log=self.log)
            self.drivers[name] = d
            d.start()
            return d

    def _release_idle(self, live: list[OperatorDriver]) -> None:
        """Stop the driver whose page left longest ago (its session stays on disk; a paused
        episode is not recorded), or raise :class:`HubFull` when every operator is here."""
        idle = [x for x in live if not x.attached and x.state in (READY, DONE)]
        if not idle:
            raise HubFull(f"the server is full ({self.max_operators} operators connected)")
        victim = min(idle, key=lambda x: x.detached_at)
        victim.stop()
        del self.drivers[victim.name]
        self.log(f"operator {victim.name}: away, released (the session stays in {victim.out})")

    def shutdown(self) -> None:
        """Stop every driver (episodes in progress are not recorded)."""
        with self._lock:
            drivers = list(self.drivers.values())
        for d in drivers:
            d.stop()
