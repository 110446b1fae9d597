"""A scripted page for protocol tests: a WebSocket client of the server that reads the scene
and frames and drives reach-pillar by the key-like commands a keyboard gives (each axis
-1, 0 or +1), on the left of the pillar (the base route) or the right."""

from __future__ import annotations

import functools
import json
from typing import Any

import anyio
import numpy as np

from elicit_jax.web.protocol import unpack

GRIPPER_OPEN = -1.0


async def _receive(rx: Any, timeout: float) -> Any:
    with anyio.fail_after(timeout):
        return await rx.receive()


class Page:
    """Wraps a Starlette ``WebSocketTestSession`` (or anything with ``send_text`` and a
    ``receive(timeout)``) and keeps what the server sent."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.texts: list[dict] = []
        self.frames: list[dict] = []
        self.clips: list[dict] = []
        self.closed: dict | None = None
        self.scene: dict | None = None
        self.state: dict | None = None

    def send(self, **msg: Any) -> None:
        self.ws.send_text(json.dumps(msg))

    def receive(self, timeout: float = 30.0) -> dict:
        """The next message, decoded (``{"type": ...}`` text, frame or clip, or close)."""
        raw = self.ws.portal.call(functools.partial(_receive, self.ws._send_rx, timeout))
        if raw["type"] == "websocket.close":
            self.closed = {"type": "close", "code": raw.get("code"), "reason": raw.get("reason")}
            return self.closed
        if raw.get("bytes") is not None:
            msg = unpack(raw["bytes"])
            (self.frames if msg["kind"] == "frame" else self.clips).append(msg)
            return {"type": msg["kind"], **msg}
        msg = json.loads(raw["text"])
        self.texts.append(msg)
        if msg["type"] == "scene":
            self.scene = msg
        if msg["type"] == "state":
            self.state = msg
        return msg

    def until(self, pred: Any, timeout: float = 60.0, limit: int = 5000) -> dict:
        """Receive until ``pred(msg)``; returns that message."""
        for _ in range(limit):
            msg = self.receive(timeout)
            if pred(msg):
                return msg
            if msg["type"] == "close":
                raise AssertionError(f"closed while waiting: {msg}")
        raise AssertionError("no such message")

    def state_where(self, **want: Any) -> dict:
        def ok(m: dict) -> bool:
            return m["type"] == "state" and all(m.get(k) == v for k, v in want.items())

        return self.until(ok)

    def events(self, kind: str) -> list[dict]:
        return [
            m["event"] for m in self.texts if m["type"] == "event" and m["event"]["kind"] == kind
        ]

    def body(self, name: str) -> int:
        assert self.scene is not None
        return self.scene["bodies"].index(name)

    def drive(self, side: int, give_up_after: int | None = None) -> dict:
        """Start the episode and steer it by frames until it ends; returns the episode-end event.

        ``side`` = +1 passes the pillar on the left (the base route), -1 on the right.
        """
        gi, oi = self.body("gripper"), self.body("goal")
        phase = 0
        self.send(type="action", a=[1, 0, 0, 0, 0, 0, GRIPPER_OPEN])
        self.send(type="start")
        steps = 0
        while True:
            msg = self.receive()
            if msg["type"] == "event" and msg["event"]["kind"] == "episode-end":
                return msg["event"]
            if msg["type"] != "frame":
                continue
            steps += 1
            if give_up_after is not None and steps >= give_up_after:
                self.send(type="give-up")
                give_up_after = None
                continue
            eef, goal = msg["poses"][gi, :3], msg["poses"][oi, :3]
            a, phase = route_command(eef, goal, side, phase)
            self.send(type="action", a=a)


def route_command(eef: np.ndarray, goal: np.ndarray, side: int, phase: int) -> tuple[list, int]:
    """Key-like command (each motion axis -1, 0, +1) past the pillar on ``side``."""

    def sign(d: float, deadband: float) -> float:
        return 0.0 if abs(d) < deadband else float(np.sign(d))

    a = [0.0] * 7
    a[6] = GRIPPER_OPEN
    if phase == 0:
        a[0], a[1] = 1.0, sign(side * 0.09 - eef[1], 0.008)
        if eef[0] >= -0.05:
            phase = 1
    if phase == 1:
        a[0], a[1], a[2] = 1.0, sign(side * 0.09 - eef[1], 0.012), sign(goal[2] - eef[2], 0.006)
        if eef[0] >= 0.06:
            phase = 2
    if phase == 2:
        d = goal - eef
        a[0], a[1], a[2] = (sign(float(x), 0.008) for x in d)
    return a, phase
