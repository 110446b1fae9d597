"""Operator secrets: whoever resumes a session must hold that operator's key.

The first page to use a new name is issued a random key (128 bits, URL-safe) in a ``key``
message; the page keeps it and sends it in every later ``hello``. The experimenter can issue
a key too (the dashboard's per-operator link), which replaces the old one. Only the key's
SHA-256 is stored, in ``SESSIONS/.operators/NAME.json`` beside the operator's session
directory, together with the operator's status (``active``, ``paused`` by the experimenter,
or ``ended``). A name whose session exists but has no key record (a session made before keys
existed, or by ``elicit-jax elicit``) is resumed only through a link the experimenter issues.
"""

from __future__ import annotations

import dataclasses
import hashlib
import hmac
import secrets
import shutil
from pathlib import Path

from elicit_jax.artifact import read_json, write_json
from elicit_jax.errors import ElicitError

KEYS_DIR = ".operators"
KIND = "operator-key"
SCHEMA_VERSION = 1
ACTIVE, PAUSED, ENDED = "active", "paused", "ended"
STATUSES = (ACTIVE, PAUSED, ENDED)


def new_key() -> str:
    """A fresh operator key."""
    return secrets.token_urlsafe(16)


def key_hash(key: str) -> str:
    """The stored form of ``key`` (hex SHA-256; the key itself is 128 random bits)."""
    return hashlib.sha256(key.encode()).hexdigest()


@dataclasses.dataclass(frozen=True)
class KeyRecord:
    """What the server keeps about an operator's key.

    Attributes:
      name: the operator.
      key_sha256: hash of the current key.
      issued_by: ``page`` (first visit) or ``experimenter`` (a link from the dashboard).
      status: ``active``, ``paused`` or ``ended``.
    """

    name: str
    key_sha256: str
    issued_by: str
    status: str = ACTIVE

    def matches(self, key: str) -> bool:
        """Does ``key`` match (constant time)?"""
        return bool(key) and hmac.compare_digest(key_hash(key), self.key_sha256)


class OperatorKeys:
    """The key records of a sessions directory ``root`` (see the module docstring)."""

    def __init__(self, root: Path) -> None:
        self.dir = Path(root) / KEYS_DIR

    def path(self, name: str) -> Path:
        """Where ``name``'s record is kept."""
        return self.dir / f"{name}.json"

    def read(self, name: str) -> KeyRecord | None:
        """The record of ``name``, or None.

        Raises:
          ElicitError: the record is malformed.
        """
        p = self.path(name)
        if not p.is_file():
            return None
        data = read_json(p)
        try:
            rec = KeyRecord(
                str(data["name"]), str(data["key_sha256"]), str(data["issued_by"]), data["status"]
            )
        except (KeyError, TypeError) as e:
            raise ElicitError(f"malformed operator key record (no {e})", p) from None
        if rec.name != name or rec.status not in STATUSES or len(rec.key_sha256) != 64:
            raise ElicitError("malformed operator key record", p)
        return rec

    def write(self, rec: KeyRecord) -> None:
        """Store ``rec`` (atomically; the key itself is never written)."""
        self.dir.mkdir(parents=True, exist_ok=True)
        body = {"kind": KIND, "schema_version": SCHEMA_VERSION, **dataclasses.asdict(rec)}
        write_json(self.path(rec.name), body)

    def issue(self, name: str, by: str) -> str:
        """Make a new key for ``name`` (replacing any; the status is kept); returns the key."""
        key = new_key()
        old = self.read(name)
        status = old.status if old is not None else ACTIVE
        self.write(KeyRecord(name, key_hash(key), by, status))
        return key

    def set_status(self, name: str, status: str) -> None:
        """Set ``name``'s status (``name`` must have a record)."""
        rec = self.read(name)
        if rec is None:
            raise ElicitError(f"operator {name!r} has no key record", self.path(name))
        self.write(dataclasses.replace(rec, status=status))

    def names(self) -> list[str]:
        """Operators with a record."""
        if not self.dir.is_dir():
            return []
        return sorted(p.stem for p in self.dir.glob("*.json"))

    def move(self, name: str, dest: Path) -> None:
        """Move ``name``'s record to ``dest`` (the operator was removed)."""
        if self.path(name).is_file():
            dest.parent.mkdir(parents=True, exist_ok=True)
            shutil.move(str(self.path(name)), dest)
