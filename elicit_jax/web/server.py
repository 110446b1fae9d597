"""The Starlette application: the page, its static files, and one WebSocket per operator.

``GET /`` serves the page, ``/static/...`` its scripts (three.js included: nothing is fetched
from elsewhere, and the page's Content-Security-Policy forbids it), and ``/ws`` is an
operator's connection: the page's first message names the operator (``hello``, with their
key once they have one), the hub admits them (:meth:`~elicit_jax.web.hub.OperatorHub.admit`:
a new name is sent its key) and attaches the connection to that operator's driver, and from
then on every message is checked (:func:`~elicit_jax.web.protocol.parse_message`, a rate
limit) and handed to the driver. A
message that breaks the protocol closes that connection alone, with the reason; a second
page of the same operator takes over and the first is closed. ``/admin`` is the
experimenter's dashboard (:mod:`elicit_jax.web.admin`); :mod:`elicit_jax.web.access` guards
everything (the ``Host`` header, tokens, origins).
"""

from __future__ import annotations

import asyncio
import contextlib
from pathlib import Path
from typing import Any

from elicit_jax.web.access import PAGE_HEADERS, AccessPolicy
from elicit_jax.web.hub import HubFull, OperatorHub, Refused
from elicit_jax.web.messages import dump
from elicit_jax.web.protocol import (
    CLOSE_FULL,
    CLOSE_POLICY,
    CLOSE_REPLACED,
    Message,
    ProtocolError,
    RateLimiter,
    parse_message,
)

STATIC = Path(__file__).parent / "static"
HELLO_TIMEOUT_S = 10.0
MAX_QUEUED = 64
"""Pose frames are dropped (never events) while this many messages wait to be sent."""


class Connection:
    """An operator's WebSocket as a driver's outbox (``send`` and ``close`` are thread-safe)."""

    def __init__(self, websocket: Any, loop: asyncio.AbstractEventLoop) -> None:
        self.websocket, self.loop = websocket, loop
        self.queue: asyncio.Queue[Any] = asyncio.Queue()
        self.dropped = 0

    def send(self, message: str | bytes, droppable: bool = False) -> None:
        with contextlib.suppress(RuntimeError):  # the loop is gone: the server is stopping
            self.loop.call_soon_threadsafe(self._put, message, droppable)

    def close(self, code: int, reason: str) -> None:
        with contextlib.suppress(RuntimeError):
            self.loop.call_soon_threadsafe(self.queue.put_nowait, (code, reason))

    def _put(self, message: str | bytes, droppable: bool) -> None:
        if droppable and self.queue.qsize() >= MAX_QUEUED:
            self.dropped += 1
            return
        self.queue.put_nowait(message)

    async def pump(self) -> None:
        """Send queued messages until a close is queued or the socket fails."""
        ws = self.websocket
        while True:
            msg = await self.queue.get()
            try:
                if isinstance(msg, tuple):
                    await ws.close(code=msg[0], reason=msg[1])
                    return
                if isinstance(msg, bytes):
                    await ws.send_bytes(msg)
                else:
                    await ws.send_text(msg)
            except Exception:  # the peer is gone; the receiving side sees the disconnect
                return


class _Disconnected(Exception):
    pass


async def _receive(
    ws: Any, limiter: RateLimiter, action_dim: int, timeout: float | None
) -> Message:
    try:
        raw = await asyncio.wait_for(ws.receive(), timeout)
    except TimeoutError:
        raise ProtocolError(CLOSE_POLICY, f"no 'hello' within {timeout:g} s") from None
    if raw["type"] == "websocket.disconnect":
        raise _Disconnected()
    limiter.take()
    text = raw.get("text")
    return parse_message(text if text is not None else raw.get("bytes", b""), action_dim)


async def operator_socket(websocket: Any) -> None:
    """One operator's connection (see the module docstring)."""
    hub: OperatorHub = websocket.app.state.hub
    await websocket.accept()
    conn = Connection(websocket, asyncio.get_running_loop())
    pump = asyncio.create_task(conn.pump())
    limiter = RateLimiter()
    driver = None
    try:
        msg = await _receive(websocket, limiter, hub.action_dim, HELLO_TIMEOUT_S)
        if msg.type != "hello":
            raise ProtocolError(CLOSE_POLICY, "the first message must be 'hello'")
        try:
            driver, key = hub.admit(msg.name, msg.key)
        except HubFull as e:
            conn.send(dump("error", message=str(e)))
            raise ProtocolError(CLOSE_FULL, str(e)) from None
        except Refused as e:
            raise ProtocolError(e.code, e.reason) from None
        if key is not None:
            conn.send(dump("key", name=driver.name, key=key))
        old = driver.attach(conn)
        if old is not None:
            old.close(CLOSE_REPLACED, "this session was opened in another window")
        while True:
            msg = await _receive(websocket, limiter, hub.action_dim, None)
            if msg.type == "hello":
                raise ProtocolError(CLOSE_POLICY, "'hello' was already sent")
            if msg.type == "ping":
                conn.send(dump("pong", t=msg.t))
            else:
                driver.handle(msg)
    except ProtocolError as e:
        conn.close(e.code, e.reason)
        with contextlib.suppress(asyncio.TimeoutError):
            await asyncio.wait_for(asyncio.shield(pump), 2.0)
    except _Disconnected:
        pass
    finally:
        if driver is not None:
            driver.detach(conn)
        pump.cancel()


def _index(request: Any) -> Any:
    from starlette.responses import FileResponse

    response = FileResponse(STATIC / "index.html", headers=PAGE_HEADERS)
    token, access = request.query_params.get("token"), request.app.state.access
    if token and access.token:
        response.set_cookie(access.token_cookie, token, httponly=True, samesite="strict")
    return response


def create_app(hub: OperatorHub, access: AccessPolicy, base_url: str | None = None) -> Any:
    """The ASGI application serving ``hub``'s operators and its dashboard under ``access``.

    Args:
      hub: the operators.
      access: who may connect (:func:`~elicit_jax.web.access.access_policy`).
      base_url: the URL operators open, for the links the dashboard issues
        (``http://127.0.0.1:PORT/`` when None).
    """
    from starlette.applications import Starlette
    from starlette.middleware import Middleware
    from starlette.routing import Mount, Route, WebSocketRoute
    from starlette.staticfiles import StaticFiles

    from elicit_jax.web.access import AccessGuard
    from elicit_jax.web.admin import NewNames, admin_routes

    @contextlib.asynccontextmanager
    async def lifespan(app: Any) -> Any:
        yield
        await asyncio.to_thread(hub.shutdown)

    app = Starlette(
        routes=[
            Route("/", _index),
            Mount("/static", StaticFiles(directory=STATIC), name="static"),
            WebSocketRoute("/ws", operator_socket),
            *admin_routes(),
        ],
        middleware=[Middleware(AccessGuard, policy=access)],
        lifespan=lifespan,
    )
    app.state.hub = hub
    app.state.access = access
    app.state.links = {}  # the dashboard's issued links, by operator (in memory only)
    app.state.new_names = NewNames()
    app.state.base_url = base_url or f"http://127.0.0.1:{access.port}/"
    return app
