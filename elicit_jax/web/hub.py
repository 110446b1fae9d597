"""All operators of one server: a driver per name, created on first contact, kept until exit.

Each operator's session lives in ``SESSIONS/<name>/``. A name seen for the first time since
the server started gets an :class:`~elicit_jax.web.driver.OperatorDriver`, which creates the
session or resumes the one in its directory — so after a server restart every operator
finds their session where they left it when their page reconnects. A driver whose session
failed to open is replaced on the next contact (the operator may retry); when the hub is
full, the driver of the operator who left longest ago is released (resumed from disk if
they come back).

Names are one operator whatever their case: "ALICE" is the existing "alice"
(:meth:`OperatorHub.canonical`), never a second session (nor a clash on a case-insensitive
file system).

Who may attach is :meth:`OperatorHub.admit`'s decision: a new name is given a key, an
existing one needs it (:mod:`elicit_jax.web.keys`), and the experimenter's pause, end and
remove (:mod:`elicit_jax.web.admin`) are enforced here.
"""

from __future__ import annotations

import dataclasses
import shutil
import threading
from collections.abc import Callable
from pathlib import Path

from elicit_jax.elicit.config import SessionConfig
from elicit_jax.errors import ElicitError
from elicit_jax.web import operator as browser_operator
from elicit_jax.web.driver import BUSY, DONE, ERROR, READY, OperatorDriver
from elicit_jax.web.keys import ACTIVE, ENDED, PAUSED, OperatorKeys
from elicit_jax.web.protocol import (
    CLOSE_ENDED,
    CLOSE_KEY,
    CLOSE_PAUSED,
    CLOSE_REMOVED,
    valid_name,
)

REMOVED_DIR = ".removed"


class HubFull(Exception):
    """No room for another operator."""


class Refused(Exception):
    """The operator may not attach now: close the page with ``code`` and ``reason``."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code, self.reason = code, reason


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
      log: where console lines go (the caller's: the CLI passes its echo).
    """

    def __init__(
        self,
        template: SessionConfig,
        root: Path,
        max_operators: int = 16,
        *,
        log: Callable[[str], None],
    ) -> None:
        self.template, self.root = template, Path(root)
        self.max_operators, self.log = max_operators, log
        self.drivers: dict[str, OperatorDriver] = {}
        self.keys = OperatorKeys(self.root)
        self._lock = threading.RLock()
        from elicit_jax.elicit.inputs import task_action_names
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

    def admit(self, name: str, key: str) -> tuple[OperatorDriver, str | None]:
        """The driver of ``name`` if ``key`` lets them in; a new name gets a key.

        Returns:
          ``(driver, new_key)``: ``new_key`` is the key just issued (a new name), else None.

        Raises:
          Refused: a wrong or missing key, a paused, ended or removed operator.
          HubFull: ``max_operators`` drivers run already.
        """
        with self._lock:
            name = self.canonical(name)
            rec = self.keys.read(name)
            if rec is None and key:
                raise Refused(
                    CLOSE_KEY,
                    f"no operator '{name}' holds this key: ask the experimenter for a link",
                )
            if rec is None and (self.root / name).exists():
                raise Refused(
                    CLOSE_KEY,
                    f"the session '{name}' has no key yet: ask the experimenter for a link",
                )
            if rec is not None and key and rec.issued_by == "experimenter" and not rec.matches(key):
                raise Refused(
                    CLOSE_KEY,
                    f"the key this page holds for '{name}' was replaced by a newer personal "
                    "link: open the newest link the experimenter gave you",
                )
            if rec is not None and not rec.matches(key):
                raise Refused(
                    CLOSE_KEY,
                    f"the name '{name}' is taken: open your personal link, or choose another name",
                )
            if rec is not None and rec.status == PAUSED:
                raise Refused(CLOSE_PAUSED, "paused by the experimenter: please wait")
            if rec is not None and rec.status == ENDED:
                raise Refused(CLOSE_ENDED, "the experimenter ended your session. Thank you!")
            driver = self.driver(name)
            return driver, (self.keys.issue(name, "page") if rec is None else None)

    def issue_key(self, name: str) -> str:
        """A new key for ``name`` (the experimenter's link); the old key stops working and a
        page attached with it is closed."""
        if not valid_name(name):
            raise ValueError(f"not an operator name: {name!r}")
        with self._lock:
            name = self.canonical(name)
            key = self.keys.issue(name, "experimenter")
            d = self.drivers.get(name)
        if d is not None:
            d.close_page(CLOSE_KEY, "the experimenter gave you a new link: open it to continue")
        return key

    def set_status(self, name: str, status: str) -> None:
        """``paused``, ``ended`` or ``active`` (resume); pausing or ending closes the page,
        ending also stops the operator's driver (an episode in progress is not recorded)."""
        with self._lock:
            if self.keys.read(name) is None:
                self.keys.issue(name, "experimenter")  # a session made before keys existed
            self.keys.set_status(name, status)
            d = self.drivers.get(name)
            if status == ENDED:
                self.drivers.pop(name, None)
        if d is not None and status == PAUSED:
            d.close_page(CLOSE_PAUSED, "paused by the experimenter: please wait")
        elif d is not None and status == ENDED:
            d.close_page(CLOSE_ENDED, "the experimenter ended your session. Thank you!")
            d.stop()

    def remove(self, name: str) -> Path | None:
        """Take ``name`` out of the study: close their page, stop their driver, and move their
        session and key to ``SESSIONS/.removed/`` (nothing is deleted). Returns where to.

        Raises:
          ElicitError: they are retraining (their policy files are being written).
        """
        with self._lock:
            d = self.drivers.get(name)
            if d is not None and d.state == BUSY:  # its files are being written
                raise ElicitError(f"operator {name} is retraining: remove them when it is over")
            self.drivers.pop(name, None)
        if d is not None:
            d.close_page(CLOSE_REMOVED, "the experimenter removed you from this study")
            d.stop(timeout=30.0)
        with self._lock:
            src = self.root / name
            n = 1
            while (self.root / REMOVED_DIR / f"{name}-{n}").exists() or (
                self.root / REMOVED_DIR / f"{name}-{n}.key.json"
            ).exists():
                n += 1
            dest = self.root / REMOVED_DIR / f"{name}-{n}"
            self.keys.move(name, dest.with_name(dest.name + ".key.json"))
            if not src.exists():
                return None
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.move(str(src), dest)
            return dest

    def canonical(self, name: str) -> str:
        """The spelling of the operator whose name is ``name`` ignoring case, else ``name``."""
        with self._lock:
            names = self.names()
        if name in names:
            return name
        folded = name.casefold()
        return next((n for n in names if n.casefold() == folded), name)

    def names(self) -> list[str]:
        """Every operator of the sessions directory: running, on disk, or with a key."""
        with self._lock:
            live = set(self.drivers)
        return sorted(live | set(session_names(self.root)) | set(self.keys.names()))

    def status_of(self, name: str) -> str:
        """``active``, ``paused`` or ``ended`` (``active`` without a key record)."""
        rec = self.keys.read(name)
        return ACTIVE if rec is None else rec.status

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
