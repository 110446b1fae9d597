"""Who may talk to the server: the right ``Host``, a token off loopback, the admin token for
the dashboard, same-origin WebSockets always.

* **Host.** Every HTTP request and WebSocket handshake must name the server by one of the
  names it was bound under (:func:`access_policy`: ``127.0.0.1``, ``localhost``, ``[::1]``,
  the ``--host`` given and any ``--allow-host``, each with the bound port); anything else gets
  400. A page on another name that resolves to 127.0.0.1 (DNS rebinding) is refused, and
  ``Host`` is never copied into a response. Bound to every address (``0.0.0.0``/``::``) the
  machine's host names and any IP-literal host with the bound port are accepted too (an IP
  literal cannot be rebound).
* **Token.** Bound to a loopback address (the default, 127.0.0.1) operators need no token:
  only this machine reaches the server. Bound anywhere else every request must carry it, as
  ``?token=...`` (the URL the server prints) or as the cookie the page sets on first load;
  anything else gets 403.
* **Cookies.** Cookies ignore ports, so every server names its cookies after its port
  (``elicit_jax_token_8765``, ``elicit_jax_admin_8765``): two servers on one machine (two
  reviews, a review beside ``serve``) never overwrite each other's.
* **Admin.** ``/admin`` and everything under it need the admin token (``?token=...`` once,
  then a cookie) even on loopback; it is distinct from the operators' token, so an operator's
  link never opens the dashboard. The admin token also passes where the operators' does.
* **Origin.** A request whose ``Origin`` is not this server's own (scheme aside: the same
  host name *and port*; a page served from another port of 127.0.0.1 is another site) is
  refused with 403, whatever its method, and so are WebSocket handshakes. Unsafe methods
  (anything but GET, HEAD, OPTIONS) must moreover come from this server's own pages: a
  browser names the page's origin in ``Origin`` (or ``Sec-Fetch-Site``) on every such
  request, so a page elsewhere cannot act through a browser that holds a cookie. A request
  with neither header is not a browser's (a script holding the token) and passes.
"""

from __future__ import annotations

import dataclasses
import hmac
import ipaddress
import secrets
import socket
from collections.abc import Iterable
from http.cookies import SimpleCookie
from typing import Any
from urllib.parse import parse_qs, urlsplit

TOKEN_COOKIE = "elicit_jax_token"
ADMIN_COOKIE = "elicit_jax_admin"
SAFE_METHODS = ("GET", "HEAD", "OPTIONS")
ADMIN_PREFIX = "/admin"
CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
    "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
)
"""The pages' Content-Security-Policy ('self' covers the same host's ws:/wss:); no ``Host``
is ever copied into it."""
PAGE_HEADERS = {"Cache-Control": "no-store", "Content-Security-Policy": CSP}
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")
WILDCARDS = ("0.0.0.0", "::", "")


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and loopback addresses (127.0.0.0/8, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def new_token() -> str:
    """A fresh random token (144 bits, URL-safe)."""
    return secrets.token_urlsafe(18)


def _bracket(name: str) -> str:
    return f"[{name}]" if ":" in name and not name.startswith("[") else name


@dataclasses.dataclass(frozen=True)
class AccessPolicy:
    """What the guard accepts.

    Attributes:
      hosts: exact ``Host`` header values accepted (lower case, ``name:port``).
      port: the bound port.
      any_ip: also accept any IP-literal host with ``port`` (bound to every address).
      token: the operators' token, or None (loopback: none needed).
      admin_token: the dashboard's token (always required under ``/admin``).
    """

    hosts: frozenset[str]
    port: int
    any_ip: bool = False
    token: str | None = None
    admin_token: str = ""

    @property
    def token_cookie(self) -> str:
        """This server's name of the operators' (or reviewer's) token cookie."""
        return f"{TOKEN_COOKIE}_{self.port}"

    @property
    def admin_cookie(self) -> str:
        """This server's name of the admin token cookie."""
        return f"{ADMIN_COOKIE}_{self.port}"

    def host_allowed(self, header: str) -> bool:
        """Is ``header`` (a request's ``Host``) one of this server's names?"""
        value = header.strip().lower()
        if value in self.hosts:
            return True
        if not self.any_ip:
            return False
        try:
            parts = urlsplit("//" + value)
            ipaddress.ip_address(parts.hostname or "")
            return parts.port == self.port and not parts.username and not parts.path
        except ValueError:
            return False


def access_policy(
    host: str,
    port: int,
    token: str | None = None,
    admin_token: str | None = None,
    extra_hosts: Iterable[str] = (),
) -> AccessPolicy:
    """The policy of a server bound to ``host:port`` (see the module docstring).

    Args:
      host: the address bound (``--host``).
      port: the port bound (the real one when ``--port 0``).
      token: the operators' token, or None.
      admin_token: the dashboard's token (made up when None).
      extra_hosts: more names operators use to reach the server (``--allow-host``).
    """
    names = {*LOOPBACK_NAMES, _bracket(host), *(_bracket(h) for h in extra_hosts)}
    wildcard = host in WILDCARDS
    if wildcard:
        names |= {socket.gethostname(), socket.getfqdn()}
    names = {n.lower() for n in names if n and n not in WILDCARDS and n != "[::]"}
    hosts = {f"{n}:{port}" for n in names} | (names if port == 80 else set())
    return AccessPolicy(
        frozenset(hosts), port, wildcard, token, admin_token if admin_token else new_token()
    )


def _headers(scope: dict[str, Any]) -> dict[str, str]:
    return {k.decode("latin-1"): v.decode("latin-1") for k, v in scope.get("headers", [])}


def _cookie(scope: dict[str, Any], name: str) -> str:
    cookie = SimpleCookie()
    try:
        cookie.load(_headers(scope).get("cookie", ""))
    except Exception:  # a malformed cookie header carries no token
        return ""
    morsel = cookie.get(name)
    return morsel.value if morsel else ""


def scope_token(scope: dict[str, Any], cookie: str) -> str:
    """The token a request carries (query parameter first, then ``cookie``), or ''."""
    query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
    if query.get("token"):
        return query["token"][0]
    return _cookie(scope, cookie)


def same_origin(scope: dict[str, Any]) -> bool:
    """False when the request names an ``Origin`` whose host or port differs from ``Host``
    (``Origin: null``, a sandboxed or file page, is another origin too)."""
    headers = _headers(scope)
    origin = headers.get("origin")
    if origin is None:
        return True
    return urlsplit(origin.strip()).netloc.lower() == headers.get("host", "").strip().lower()


def from_own_page(scope: dict[str, Any]) -> bool:
    """May this request change something? True for safe methods; an unsafe one must name
    this server as its origin (``Origin``, else ``Sec-Fetch-Site: same-origin``); one with
    neither header is not a browser's and passes (the token still decides)."""
    if scope["type"] == "http" and scope.get("method") in SAFE_METHODS:
        return True
    headers = _headers(scope)
    if "origin" in headers:
        return same_origin(scope)
    return headers.get("sec-fetch-site", "same-origin") in ("same-origin", "none")


def is_admin_path(path: str) -> bool:
    """Is ``path`` the dashboard or under it (``/admin``, ``/admin/...``)?"""
    return path == ADMIN_PREFIX or path.startswith(ADMIN_PREFIX + "/")


def _equal(given: str, want: str | None) -> bool:
    return bool(want) and hmac.compare_digest(given.encode(), str(want).encode())


class AccessGuard:
    """ASGI middleware enforcing the rules of the module docstring.

    Args:
      app: the wrapped application.
      policy: what is accepted.
    """

    def __init__(self, app: Any, policy: AccessPolicy) -> None:
        self.app, self.policy = app, policy

    def verdict(self, scope: dict[str, Any]) -> int:
        """0 (allowed), 400 (unknown ``Host``) or 403 (no token, another origin)."""
        p = self.policy
        if not p.host_allowed(_headers(scope).get("host", "")):
            return 400
        if not same_origin(scope) or not from_own_page(scope):
            return 403
        admin = _equal(scope_token(scope, p.admin_cookie), p.admin_token) or _equal(
            _cookie(scope, p.admin_cookie), p.admin_token
        )
        if is_admin_path(scope.get("path", "")):
            return 0 if admin else 403
        if p.token is None or admin:
            return 0
        return 0 if _equal(scope_token(scope, p.token_cookie), p.token) else 403

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        status = self.verdict(scope) if scope["type"] in ("http", "websocket") else 0
        if status == 0:
            await self.app(scope, receive, send)
            return
        body = (
            b"bad request: this server answers only to the names it was started with\n"
            if status == 400
            else b"forbidden: open the URL the server printed (it carries the access token)\n"
        )
        start = "http.response.start"
        if scope["type"] == "websocket":
            await receive()  # the handshake's websocket.connect, answered with a refusal
            if status == 403 or "websocket.http.response" not in scope.get("extensions", {}):
                # a close before accepting: the server answers 403
                await send({"type": "websocket.close", "code": 1008, "reason": "not allowed"})
                return
            start = "websocket.http.response.start"  # an HTTP 400 (denial response)
        headers = [(b"content-type", b"text/plain"), (b"content-length", b"%d" % len(body))]
        await send({"type": start, "status": status, "headers": headers})
        await send({"type": start.replace(".start", ".body"), "body": body})
