"""The server's front door, in-process (Starlette TestClient): the Host check (DNS
rebinding), operator names matched whole, operator keys, and the dashboard's token and
actions. Sessions run on the `serve --demo` inputs (the session-scoped fixture)."""

from __future__ import annotations

import hashlib
import json

import pytest
from clients import client_for
from pages import Page
from starlette.testclient import WebSocketDenialResponse
from starlette.websockets import WebSocketDisconnect

from elicit_jax.web.access import AccessGuard, access_policy
from elicit_jax.web.hub import OperatorHub
from elicit_jax.web.keys import KEYS_DIR, key_hash
from elicit_jax.web.protocol import (
    CLOSE_ENDED,
    CLOSE_KEY,
    CLOSE_PAUSED,
    CLOSE_POLICY,
    CLOSE_REMOVED,
    ProtocolError,
    parse_message,
    valid_name,
)
from elicit_jax.web.server import create_app

ADMIN = "admin-secret-123"


@pytest.fixture
def served(template, tmp_path):
    """(client, hub) of a fresh loopback server on 127.0.0.1:8765, sessions in tmp_path."""
    hubs = []

    def make(token=None):
        hub = OperatorHub(template, tmp_path / "sessions", 4, log=lambda _: None)
        hubs.append(hub)
        policy = access_policy("127.0.0.1", 8765, token, admin_token=ADMIN)
        return client_for(create_app(hub, policy)), hub

    yield make
    for hub in hubs:
        hub.shutdown()


def hello(client, name: str, key: str | None = None, until_state: bool = True) -> Page:
    page = Page(client.websocket_connect("/ws").__enter__())
    page.send(type="hello", name=name, **({"key": key} if key else {}))
    if until_state:
        page.until(lambda m: m["type"] in ("state", "close") and m.get("state") != "opening")
    return page


def closed(page: Page) -> dict:
    return page.until(lambda m: m["type"] == "close")


def refused(client, name: str, key: str | None = None) -> dict:
    page = hello(client, name, key, until_state=False)
    msg = page.receive()
    assert msg["type"] == "close", msg
    return msg


# --- the Host header ---------------------------------------------------------------------


def test_only_the_bound_names_are_answered_and_host_is_never_echoed(served):
    client, _ = served()
    for host in ("127.0.0.1:8765", "localhost:8765", "[::1]:8765", "LOCALHOST:8765"):
        r = client.get("/", headers={"host": host})
        assert r.status_code == 200, host
        assert "localhost" not in r.headers["content-security-policy"].lower()
        assert "connect-src 'self';" in r.headers["content-security-policy"]
    for host in ("rebind.attacker.example:8765", "127.0.0.1:9999", "127.0.0.1", "", "a b"):
        r = client.get("/", headers={"host": host})
        assert r.status_code == 400, host
        assert "attacker" not in r.text and "bad request" in r.text
    assert client.get("/static/app.js", headers={"host": "evil.example:8765"}).status_code == 400
    with (
        pytest.raises(WebSocketDenialResponse) as e,
        client.websocket_connect("/ws", headers={"host": "rebind.attacker.example:8765"}),
    ):
        pass
    assert e.value.status_code == 400


def test_access_policy_names():
    lo = access_policy("127.0.0.1", 8765)
    assert lo.host_allowed("localhost:8765") and lo.host_allowed("[::1]:8765")
    assert not lo.host_allowed("10.0.0.7:8765")  # an IP literal, but not a bound one
    lab = access_policy("lab-pc.example", 80, token="t0ken-abc", extra_hosts=("10.1.2.3",))
    assert lab.host_allowed("lab-pc.example") and lab.host_allowed("lab-pc.example:80")
    assert lab.host_allowed("10.1.2.3:80") and not lab.host_allowed("other.example")
    every = access_policy("0.0.0.0", 8000)
    assert every.host_allowed("192.168.4.20:8000") and every.host_allowed("[fe80::1]:8000")
    assert not every.host_allowed("192.168.4.20:8001")  # the wrong port
    assert not every.host_allowed("rebind.example:8000")
    assert access_policy("127.0.0.1", 1).admin_token != access_policy("127.0.0.1", 1).admin_token


def test_the_guard_answers_400_to_a_websocket_without_the_denial_extension():
    sent = []

    async def receive():
        return {"type": "websocket.connect"}

    async def send(msg):
        sent.append(msg)

    guard = AccessGuard(None, access_policy("127.0.0.1", 8765))
    scope = {"type": "websocket", "path": "/ws", "headers": [(b"host", b"evil:8765")]}
    import asyncio
    import threading

    # in a thread of its own: Playwright's sync API (a session fixture) keeps a loop running here
    worker = threading.Thread(target=asyncio.run, args=(guard(scope, receive, send),))
    worker.start()
    worker.join()
    assert sent == [{"type": "websocket.close", "code": 1008, "reason": "not allowed"}]


# --- names -------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["eve\n", "eve\r\n", "\neve", "eve ", "", "a" * 41, "é"])
def test_an_operator_name_must_match_whole(name):
    assert not valid_name(name)
    with pytest.raises(ProtocolError, match="operator name"):
        parse_message(json.dumps({"type": "hello", "name": name}), 7)


def test_a_name_with_a_trailing_newline_makes_no_directory(served, tmp_path):
    client, _ = served()
    msg = refused(client, "eve\n")
    assert msg["code"] == CLOSE_POLICY and "operator name" in msg["reason"]
    assert not (tmp_path / "sessions" / "eve\n").exists()
    assert valid_name("eve") and valid_name("op_4-b")


# --- operator keys -----------------------------------------------------------------------


def test_a_new_name_gets_a_key_and_only_its_hash_is_stored(served, tmp_path):
    client, hub = served()
    first = hello(client, "ana")
    key = next(m for m in first.texts if m["type"] == "key")
    assert key["name"] == "ana" and len(key["key"]) >= 16
    record = (tmp_path / "sessions" / KEYS_DIR / "ana.json").read_text()
    assert key["key"] not in record
    assert json.loads(record)["key_sha256"] == hashlib.sha256(key["key"].encode()).hexdigest()

    # someone else typing "ana": refused, with or without a made-up key; ana's page stays
    for guess in (None, "x" * 22, key["key"][:-1] + ("A" if key["key"][-1] != "A" else "B")):
        msg = refused(client, "ana", guess)
        assert msg["code"] == CLOSE_KEY and "taken" in msg["reason"], guess
    first.send(type="ping", t=1)
    assert first.until(lambda m: m["type"] in ("pong", "close"))["type"] == "pong"

    # ana herself, with her key: resumes (her other window is closed), and no new key
    again = hello(client, "ana", key["key"])
    assert closed(first)["code"] == 4000
    assert not [m for m in again.texts if m["type"] == "key"] and again.state["state"] == "ready"
    again.ws.__exit__(None, None, None)

    # a key for a name nobody holds; a session without a key record (made before keys)
    assert refused(client, "bo", "y" * 22)["code"] == CLOSE_KEY
    (tmp_path / "sessions" / "old").mkdir()
    (tmp_path / "sessions" / "old" / "artifact.json").write_text("{}")
    msg = refused(client, "old")
    assert msg["code"] == CLOSE_KEY and "experimenter" in msg["reason"]
    link_key = hub.issue_key("old")  # the experimenter's link lets the operator in
    assert hub.keys.read("old").matches(link_key) and hub.keys.read("old").issued_by == (
        "experimenter"
    )
    assert key_hash(link_key) in (tmp_path / "sessions" / KEYS_DIR / "old.json").read_text()


# --- the dashboard -----------------------------------------------------------------------


def test_the_dashboard_needs_its_own_token_even_on_loopback(served):
    client, _ = served(token="operator-token")
    assert client.get("/admin").status_code == 403
    assert client.get("/admin?token=operator-token").status_code == 403  # operators' token
    assert client.get("/admin/api/state?token=operator-token").status_code == 403
    r = client.get(f"/admin?token={ADMIN}")
    assert r.status_code == 200 and "admin.js" in r.text
    assert "elicit_jax_admin_8765=" in r.headers["set-cookie"]  # named after the port
    page = client.get("/?token=operator-token")
    assert "elicit_jax_token_8765=operator-token" in page.headers["set-cookie"]
    assert client.get("/admin/api/state").status_code == 200  # the cookie carries it now
    assert client.get("/static/admin.js").status_code == 200
    for origin in ("http://evil.example", "http://127.0.0.1:9999", "null"):  # other sites
        foreign = {"origin": origin}
        assert client.post("/admin/api/operators/ana/link", headers=foreign).status_code == 403
    own = {"origin": "http://127.0.0.1:8765"}
    assert client.post("/admin/api/operators/ana/link?create=1", headers=own).status_code == 200
    client.cookies.clear()
    assert client.get("/admin/api/state").status_code == 403
    loopback, _ = served()
    assert loopback.get("/admin").status_code == 403


def test_dashboard_links_pause_end_and_remove(served, tmp_path):
    client, _ = served()
    client.get(f"/admin?token={ADMIN}")
    link = client.post("/admin/api/operators/cy/link?create=1").json()["link"]
    assert link.startswith("http://127.0.0.1:8765/#op=cy&key=")
    key = link.split("key=")[1]
    cy = hello(client, "cy", key)
    assert cy.state["state"] == "ready" and not [m for m in cy.texts if m["type"] == "key"]
    rows = {r["name"]: r for r in client.get("/admin/api/state").json()["operators"]}
    assert rows["cy"]["page"] and rows["cy"]["screen"] == "practice"
    assert rows["cy"]["counts"]["accepted"] == 0 and rows["cy"]["status"] == "active"

    assert client.post("/admin/api/operators/cy/pause").json()["status"] == "paused"
    assert closed(cy)["code"] == CLOSE_PAUSED
    assert refused(client, "cy", key)["code"] == CLOSE_PAUSED
    client.post("/admin/api/operators/cy/resume")
    cy = hello(client, "cy", key)
    assert cy.state["state"] == "ready"

    new = client.post("/admin/api/operators/cy/link").json()["link"].split("key=")[1]
    assert closed(cy)["code"] == CLOSE_KEY  # the old key stops working at once
    assert refused(client, "cy", key)["code"] == CLOSE_KEY
    cy = hello(client, "cy", new)

    client.post("/admin/api/operators/cy/end")
    assert closed(cy)["code"] == CLOSE_ENDED
    assert refused(client, "cy", new)["code"] == CLOSE_ENDED
    row = client.get("/admin/api/state").json()["operators"][0]
    assert (row["name"], row["status"], row["page"]) == ("cy", "ended", False)

    r = client.get("/admin/download/merged.parquet")
    assert r.status_code == 404 and "no session here has accepted" in r.text
    assert client.post("/admin/api/operators/nobody/pause").status_code == 404
    assert client.post("/admin/api/operators/cy/explode").status_code == 404

    cy = hello(client, "dee")
    moved = client.post("/admin/api/operators/dee/remove").json()["moved_to"]
    assert closed(cy)["code"] == CLOSE_REMOVED
    assert moved.endswith(".removed/dee-1")
    assert (tmp_path / "sessions" / ".removed" / "dee-1" / "artifact.json").is_file()
    assert not (tmp_path / "sessions" / "dee").exists()
    assert [r["name"] for r in client.get("/admin/api/state").json()["operators"]] == ["cy"]

    # `elicit-jax info SESSIONS/`: one row per operator, the removed one counted apart
    from typer.testing import CliRunner

    from elicit_jax.cli import app

    info = CliRunner().invoke(app, ["info", str(tmp_path / "sessions")], env={"COLUMNS": "200"})
    assert info.exit_code == 0, info.output
    assert "1 operator(s), 0 accepted demonstration(s) in all" in info.output
    assert "removed from the study (not counted): 1" in info.output
    assert any(ln.startswith("│ cy ") and "0/1" in ln for ln in info.output.splitlines())


def test_websocket_refused_without_the_token_off_loopback(served):
    client, _ = served(token="operator-token")
    with pytest.raises(WebSocketDisconnect) as e, client.websocket_connect("/ws"):
        pass
    assert e.value.code == 1008  # closed before the handshake: the server answers 403
    origin = {"origin": "http://x.example"}
    with (
        pytest.raises(WebSocketDisconnect) as e,
        client.websocket_connect("/ws?token=operator-token", headers=origin),
    ):
        pass
    assert e.value.code == 1008 and not isinstance(e.value, WebSocketDenialResponse)


def test_dashboard_names_ignore_case_new_ones_are_confirmed_and_limited(served, tmp_path):
    from elicit_jax.web.admin import MAX_NEW_PER_MINUTE

    client, hub = served()
    client.get(f"/admin?token={ADMIN}")
    r = client.post("/admin/api/operators/alice/link")
    assert r.status_code == 409 and r.json()["new"] and "confirm" in r.json()["error"]
    assert hub.names() == []  # nothing was created
    link = client.post("/admin/api/operators/alice/link?create=1").json()["link"]
    again = client.post("/admin/api/operators/ALICE/link")  # alice herself: no confirmation
    assert again.status_code == 200 and again.json()["name"] == "alice"
    assert "#op=alice&key=" in again.json()["link"] and again.json()["link"] != link
    key = again.json()["link"].split("key=")[1]
    assert refused(client, "Alice")["code"] == CLOSE_KEY  # her name, typed in capitals
    page = hello(client, "ALICE", key)  # her key opens her session whatever the case
    assert page.state["state"] == "ready"
    assert hub.names() == ["alice"] and not (tmp_path / "sessions" / "ALICE").exists()
    assert client.post("/admin/api/operators/Alice/pause").json()["status"] == "paused"
    assert closed(page)["code"] == CLOSE_PAUSED

    st = client.get("/admin/api/state").json()
    assert [r["name"] for r in st["operators"]] == ["alice"]
    assert st["links"] == [{"name": "alice", "link": again.json()["link"]}]  # the newest
    made = [
        client.post(f"/admin/api/operators/op{i}/link?create=1").status_code
        for i in range(MAX_NEW_PER_MINUTE + 1)
    ]
    assert made == [200] * (MAX_NEW_PER_MINUTE - 1) + [429, 429]  # alice was the first
    assert client.post("/admin/api/operators/op0/link").status_code == 200  # not new
    assert len(client.get("/admin/api/state").json()["links"]) == MAX_NEW_PER_MINUTE
    client.post("/admin/api/operators/op0/remove")
    names = [x["name"] for x in client.get("/admin/api/state").json()["links"]]
    assert "op0" not in names and len(names) == MAX_NEW_PER_MINUTE - 1
