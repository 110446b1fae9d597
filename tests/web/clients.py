"""Starlette TestClients that reach the server by an allowed name (``127.0.0.1:8765``): the
server refuses any other ``Host`` (DNS rebinding), and TestClient's WebSockets otherwise say
``testserver``."""

from __future__ import annotations

from typing import Any

HOST = "127.0.0.1:8765"
BASE = f"http://{HOST}"


def client_for(app: Any, host: str = HOST) -> Any:
    """A TestClient of ``app`` whose requests and WebSockets carry ``Host: host``."""
    from starlette.testclient import TestClient

    class Client(TestClient):
        def websocket_connect(self, url: str, subprotocols: Any = None, **kwargs: Any) -> Any:
            headers = {"host": host, **dict(kwargs.pop("headers", None) or {})}
            return super().websocket_connect(url, subprotocols, headers=headers, **kwargs)

    return Client(app, base_url=f"http://{host}")
