"""Who may talk to the server: a token off loopback, same-origin WebSockets always.

Bound to a loopback address (the default, 127.0.0.1) the server needs no token: only this
machine reaches it. Bound anywhere else it requires one: every HTTP request and WebSocket
handshake must carry it, as ``?token=...`` (the URL the server prints) or as the cookie the
page sets on first load; anything else gets 403. WebSocket handshakes whose ``Origin`` is
another site are refused everywhere, so a page on another site cannot drive an operator's
robot through their browser.
"""

from __future__ import annotations

import hmac
import ipaddress
import secrets
from http.cookies import SimpleCookie
from typing import Any
from urllib.parse import parse_qs, urlsplit

TOKEN_COOKIE = "elicit_jax_token"


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (127.0.0.0/8, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def new_token() -> str:
    return secrets.token_urlsafe(18)


def _headers(scope: dict[str, Any]) -> dict[str, str]:
    return {k.decode("latin-1"): v.decode("latin-1") for k, v in scope.get("headers", [])}


def scope_token(scope: dict[str, Any]) -> str:
    """The token a request carries (query parameter first, then the cookie), or ''."""
    query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
    if query.get("token"):
        return query["token"][0]
    cookie = SimpleCookie()
    try:
        cookie.load(_headers(scope).get("cookie", ""))
    except Exception:  # a malformed cookie header carries no token
        return ""
    morsel = cookie.get(TOKEN_COOKIE)
    return morsel.value if morsel else ""


def same_origin(scope: dict[str, Any]) -> bool:
    """False when the request names an ``Origin`` whose host differs from ``Host``."""
    headers = _headers(scope)
    origin = headers.get("origin")
    if not origin:
        return True
    return urlsplit(origin).netloc.lower() == headers.get("host", "").lower()


class AccessGuard:
    """ASGI middleware enforcing the rules of the module docstring.

    Args:
      app: the wrapped application.
      token: required token, or None (loopback).
    """

    def __init__(self, app: Any, token: str | None) -> None:
        self.app, self.token = app, token

    def allowed(self, scope: dict[str, Any]) -> bool:
        if scope["type"] == "websocket" and not same_origin(scope):
            return False
        if self.token is None:
            return True
        return hmac.compare_digest(scope_token(scope).encode(), self.token.encode())

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] not in ("http", "websocket") or self.allowed(scope):
            await self.app(scope, receive, send)
            return
        if scope["type"] == "websocket":
            await receive()  # the handshake's websocket.connect, answered with a refusal
            await send({"type": "websocket.close", "code": 1008, "reason": "not allowed"})
            return
        body = b"forbidden: open the URL the server printed (it carries the access token)\n"
        await send(
            {
                "type": "http.response.start",
                "status": 403,
                "headers": [
                    (b"content-type", b"text/plain"),
                    (b"content-length", b"%d" % len(body)),
                ],
            }
        )
        await send({"type": "http.response.body", "body": body})
