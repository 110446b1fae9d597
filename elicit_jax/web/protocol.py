"""The wire protocol between a browser and ``elicit-jax serve``: checked messages, binary poses.

**Browser → server**: JSON text messages of at most :data:`MAX_MESSAGE_BYTES` bytes, each an
object with a ``type``:

=============  =====================================  ==========================================
type           fields                                 meaning
=============  =====================================  ==========================================
``hello``      ``name`` (1-40 of ``A-Z a-z 0-9 _ -``)  first message: attach to that operator's
               and ``key`` (optional: the operator's  session (created or resumed); a new name
               secret, 16-64 of ``A-Z a-z 0-9 _ -``)  is answered with a ``key`` message, an
                                                      existing one needs its key
``action``     ``a``: list of ``action_dim`` numbers   the operator's current command; the server
               in [-1, 1]                             applies the latest one at each control step
``control``    ``operator``: bool                     HG-DAgger: take over (true) / hand back
``start``      —                                      start (or resume) stepping the episode
``give-up``    —                                      end the current episode now (not solved)
``ping``       ``t``: number                          answered with ``pong``
=============  =====================================  ==========================================

Anything else — a binary message, invalid JSON (NaN and Infinity included), an unknown type or
field, a wrong type or range, a name that is not allowed, more than :data:`RATE_PER_S`
messages a second on average (bursts up to :data:`RATE_BURST`) — raises
:class:`ProtocolError` with a WebSocket close code and a one-line reason; the server closes
that connection only.

**Server → browser**: JSON text messages (``key``, ``welcome``, ``scene``, ``state``,
``event``, ``prompt``, ``review``, ``error``, ``pong``) and binary pose messages, little-endian:

* frame (:func:`pack_frame`): ``u8 kind=1, u8 flags (bit 0: the operator controls the robot),
  u16 nbody, u32 episode, u32 step, f32 M (NaN: not scored or hidden)`` then
  ``nbody x 7`` float32 body poses ``(x, y, z, qw, qx, qy, qz)``;
* clip (:func:`pack_clip`): ``u8 kind=2, u8 role (0 prompt, 1 your window, 2 base segment),
  u16 nbody, u32 id, u32 T, u32 reserved`` then ``T x nbody x 7`` float32.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import struct
import time
from typing import Any

import numpy as np

PROTOCOL_VERSION = 2
MAX_MESSAGE_BYTES = 512
RATE_PER_S = 120.0
RATE_BURST = 240.0
NAME_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,39}")
"""Operator names; always used with ``fullmatch`` (``$`` would let a trailing newline in)."""
KEY_RE = re.compile(r"[A-Za-z0-9_-]{16,64}")
NAME_RULE = "1-40 letters, digits, '_' or '-', starting with a letter or digit"

CLOSE_NORMAL = 1000
CLOSE_UNSUPPORTED = 1003
CLOSE_POLICY = 1008
CLOSE_TOO_BIG = 1009
CLOSE_REPLACED = 4000
CLOSE_FULL = 4001
CLOSE_SESSION = 4002
CLOSE_KEY = 4003
"""The name is taken and the key is missing or wrong (the page stops retrying)."""
CLOSE_PAUSED = 4004
"""The experimenter paused the operator (the page retries, and is let in once resumed)."""
CLOSE_ENDED = 4005
CLOSE_REMOVED = 4006

FRAME = 1
CLIP = 2
ROLE_PROMPT, ROLE_YOURS, ROLE_BASE = 0, 1, 2
_FRAME_HEAD = struct.Struct("<BBHIIf")
_CLIP_HEAD = struct.Struct("<BBHIII")


class ProtocolError(Exception):
    """A message breaks the protocol: close the connection with ``code`` and ``reason``."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason[:120]


@dataclasses.dataclass(frozen=True)
class Message:
    """A checked browser message: ``type`` and its fields."""

    type: str
    name: str = ""
    key: str = ""
    action: tuple[float, ...] = ()
    operator: bool = False
    t: float = 0.0


_OPTIONAL = {"hello": {"key"}}
_FIELDS = {
    "hello": {"name"},
    "action": {"a"},
    "control": {"operator"},
    "start": set(),
    "give-up": set(),
    "ping": {"t"},
}


def valid_name(name: object) -> bool:
    """Is ``name`` an allowed operator name (the whole string, see :data:`NAME_RULE`)?"""
    return isinstance(name, str) and NAME_RE.fullmatch(name) is not None


def _reject_constant(token: str) -> Any:
    raise ValueError(f"{token} is not allowed")


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def parse_message(raw: str | bytes | None, action_dim: int) -> Message:
    """Check one browser message and return it as a :class:`Message`.

    Args:
      raw: the text (``str``) of the message; ``bytes`` are a binary message (refused).
      action_dim: length of the ``action`` vector.

    Raises:
      ProtocolError: anything but a valid message (see the module docstring).
    """
    if not isinstance(raw, str):
        raise ProtocolError(CLOSE_UNSUPPORTED, "binary messages are not accepted")
    if len(raw.encode()) > MAX_MESSAGE_BYTES:
        raise ProtocolError(CLOSE_TOO_BIG, f"message longer than {MAX_MESSAGE_BYTES} bytes")
    try:
        data = json.loads(raw, parse_constant=_reject_constant)
    except ValueError as e:
        raise ProtocolError(CLOSE_POLICY, f"not valid JSON: {e}") from None
    if not isinstance(data, dict):
        raise ProtocolError(CLOSE_POLICY, "a message must be a JSON object")
    kind = data.get("type")
    if kind not in _FIELDS:
        raise ProtocolError(CLOSE_POLICY, f"unknown message type {str(kind)[:30]!r}")
    extra = set(data) - _FIELDS[kind] - _OPTIONAL.get(kind, set()) - {"type"}
    if extra:
        raise ProtocolError(CLOSE_POLICY, f"'{kind}' has unknown field(s) {sorted(extra)}")
    missing = _FIELDS[kind] - set(data)
    if missing:
        raise ProtocolError(CLOSE_POLICY, f"'{kind}' lacks field(s) {sorted(missing)}")
    if kind == "hello":
        name = data["name"]
        if not valid_name(name):
            raise ProtocolError(CLOSE_POLICY, f"operator name must be {NAME_RULE}")
        key = data.get("key", "")
        if not isinstance(key, str) or (key and not KEY_RE.fullmatch(key)):
            raise ProtocolError(CLOSE_POLICY, "'key' must be 16-64 letters, digits, '_' or '-'")
        return Message(kind, name=name, key=key)
    if kind == "action":
        a = data["a"]
        if not isinstance(a, list) or len(a) != action_dim:
            raise ProtocolError(CLOSE_POLICY, f"'a' must be a list of {action_dim} numbers")
        if not all(_number(v) and -1.0 <= v <= 1.0 for v in a):
            raise ProtocolError(CLOSE_POLICY, "action values must be finite numbers in [-1, 1]")
        return Message(kind, action=tuple(float(v) for v in a))
    if kind == "control":
        if not isinstance(data["operator"], bool):
            raise ProtocolError(CLOSE_POLICY, "'operator' must be true or false")
        return Message(kind, operator=data["operator"])
    if kind == "ping":
        if not _number(data["t"]):
            raise ProtocolError(CLOSE_POLICY, "'t' must be a finite number")
        return Message(kind, t=float(data["t"]))
    return Message(kind)


class RateLimiter:
    """A token bucket: ``rate`` messages a second on average, bursts up to ``burst``."""

    def __init__(self, rate: float = RATE_PER_S, burst: float = RATE_BURST) -> None:
        self.rate, self.burst = rate, burst
        self.tokens = burst
        self.last = time.monotonic()

    def take(self, now: float | None = None) -> None:
        """Spend one token.

        Raises:
          ProtocolError: the bucket is empty (the sender is too fast).
        """
        now = time.monotonic() if now is None else now
        self.tokens = min(self.burst, self.tokens + (now - self.last) * self.rate)
        self.last = now
        if self.tokens < 1.0:
            raise ProtocolError(
                CLOSE_POLICY, f"too many messages (more than {self.rate:g} a second)"
            )
        self.tokens -= 1.0


def pack_frame(
    poses: np.ndarray, episode: int, step: int, m: float = math.nan, operator: bool = True
) -> bytes:
    """A binary pose frame of ``poses (nbody, 7)`` (see the module docstring)."""
    p = np.ascontiguousarray(poses, "<f4")
    head = _FRAME_HEAD.pack(FRAME, int(operator), p.shape[0], episode, step, m)
    return head + p.tobytes()


def pack_clip(poses: np.ndarray, role: int, ident: int) -> bytes:
    """A binary clip of ``poses (T, nbody, 7)`` (see the module docstring)."""
    p = np.ascontiguousarray(poses, "<f4")
    return _CLIP_HEAD.pack(CLIP, role, p.shape[1], ident, p.shape[0], 0) + p.tobytes()


def unpack(data: bytes) -> dict[str, Any]:
    """Decode a binary frame or clip (for tests, tools and the load benchmark)."""
    kind = data[0]
    if kind == FRAME:
        _, flags, nbody, episode, step, m = _FRAME_HEAD.unpack_from(data)
        poses = np.frombuffer(data, "<f4", offset=_FRAME_HEAD.size).reshape(nbody, 7)
        return {
            "kind": "frame",
            "operator": bool(flags & 1),
            "episode": episode,
            "step": step,
            "m": m,
            "poses": poses,
        }
    if kind == CLIP:
        _, role, nbody, ident, length, _ = _CLIP_HEAD.unpack_from(data)
        poses = np.frombuffer(data, "<f4", offset=_CLIP_HEAD.size).reshape(length, nbody, 7)
        return {"kind": "clip", "role": role, "id": ident, "poses": poses}
    raise ValueError(f"unknown binary message kind {kind}")
