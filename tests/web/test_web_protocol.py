"""The server over its WebSocket protocol, in-process with Starlette's TestClient (no browser).

Sessions run on the `serve --demo` inputs (reach-pillar). A scripted page steers by key-like
commands from the streamed poses: past the pillar on the left (the base route, accepted) or
on the right (rejected, with feedback).
"""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
from clients import client_for
from pages import Page

from elicit_jax.data.demos import read_demos
from elicit_jax.elicit.store import SessionStore
from elicit_jax.web.access import access_policy
from elicit_jax.web.hub import OperatorHub
from elicit_jax.web.protocol import (
    CLOSE_FULL,
    CLOSE_POLICY,
    CLOSE_REPLACED,
    CLOSE_TOO_BIG,
    CLOSE_UNSUPPORTED,
    MAX_MESSAGE_BYTES,
    ROLE_BASE,
    ROLE_PROMPT,
    ROLE_YOURS,
)
from elicit_jax.web.server import create_app

ADMIN = "admin-token-for-tests"


@pytest.fixture
def make_client(template, tmp_path):
    """make(root=..., token=..., max_operators=...) -> TestClient of a fresh hub, reaching the
    server as 127.0.0.1:8765. The operators' keys are kept across the test's clients."""
    made = []
    keys: dict[str, str] = {}

    def make(root=None, token=None, max_operators=16, **settings):
        import dataclasses

        config = dataclasses.replace(template, **settings)
        hub = OperatorHub(config, root or tmp_path / "sessions", max_operators, log=lambda _: None)
        policy = access_policy("127.0.0.1", 8765, token, admin_token=ADMIN)
        client = client_for(create_app(hub, policy))
        client.keys = keys
        made.append(hub)
        return client

    yield make
    for hub in made:
        hub.shutdown()


def _join(client, name: str) -> Page:
    """A page of operator ``name``: their key if they have one (kept when issued)."""
    ws = client.websocket_connect("/ws").__enter__()
    page = Page(ws)
    key = client.keys.get(name)
    page.send(type="hello", name=name, **({"key": key} if key else {}))
    page.until(lambda m: m["type"] == "state" and m["state"] not in ("opening",))
    issued = [m["key"] for m in page.texts if m["type"] == "key"]
    assert len(issued) == (0 if key else 1)  # a key for a new name, none on a resume
    client.keys.setdefault(name, *issued[:1])
    return page


def test_page_static_files_and_csp(make_client):
    client = make_client()
    r = client.get("/")
    assert r.status_code == 200
    csp = r.headers["content-security-policy"]
    assert "default-src 'self'" in csp and "script-src 'self'" in csp
    assert '<script type="module" src="/static/app.js">' in r.text
    three = client.get("/static/three/three.module.js")
    assert three.status_code == 200 and "javascript" in three.headers["content-type"]
    assert "MIT License" in client.get("/static/three/LICENSE").text


def test_a_session_from_practice_to_an_accepted_demonstration(make_client, tmp_path):
    """practice → prompt (clips) → a rejected demo with feedback clips → an accepted one."""
    client = make_client()
    page = _join(client, "alice")
    welcome = next(m for m in page.texts if m["type"] == "welcome")
    assert (welcome["task"], welcome["mode"], welcome["control_hz"]) == (
        "reach-pillar",
        "informed",
        20,
    )
    assert welcome["rule"].startswith("reject when more than 5%")
    assert {i["type"] for i in page.scene["items"]} == {"plane", "capsule", "box", "sphere"}
    state = page.state
    assert (state["state"], state["episode_kind"], state["step"]) == ("ready", "practice", 0)

    # practice: paced at the control rate; the frames carry no M (no indicator in practice)
    t0 = time.perf_counter()
    end = page.drive(+1)
    assert end["episode_kind"] == "practice" and end["success"]
    frames = [f for f in page.frames if f["episode"] == 0 and f["step"] > 0]
    assert [f["step"] for f in frames] == list(range(1, end["length"] + 1))
    assert time.perf_counter() - t0 >= 0.9 * 0.05 * (end["length"] - 1)  # never faster than 20 Hz
    assert all(np.isnan(f["m"]) for f in frames)
    assert page.state_where(state="ready", review_pending=True)

    # the prompt: 2 base demonstrations, each replayed by a clip of its poses
    prompt = next(m for m in page.texts if m["type"] == "prompt")
    assert len(prompt["episodes"]) == 2 and all(e["exact"] for e in prompt["episodes"])
    clips = [c for c in page.clips if c["role"] == ROLE_PROMPT]
    assert [len(c["poses"]) for c in clips] == [e["length"] for e in prompt["episodes"]]
    assert page.state["prompt_pending"]

    # a demonstration past the right of the pillar: red indicators, rejected, feedback clips
    end = page.drive(-1)
    assert end["episode_kind"] == "demonstration" and end["success"] and not end["counted"]
    review = page.until(lambda m: m["type"] == "review")
    assert review["verdict"] == "rejected" and len(review["windows"]) == 3
    indicators = page.events("indicator")
    assert any(i["incompatible"] for i in indicators)
    assert [i["step"] for i in indicators] == list(range(end["length"]))
    m = [f["m"] for f in page.frames if f["episode"] == 1 and f["step"] > 0]
    np.testing.assert_allclose(m, [i["compatibility"] for i in indicators], rtol=1e-6)
    page.until(lambda m: m["type"] == "state" and m["review_pending"])
    for i, w in enumerate(review["windows"]):
        yours = [c for c in page.clips if c["role"] == ROLE_YOURS and c["id"] == i]
        base = [c for c in page.clips if c["role"] == ROLE_BASE and c["id"] == i]
        assert len(yours[0]["poses"]) == w["stop"] - w["start"] == len(w["m"])
        assert len(base[0]["poses"]) == w["base_stop"] - w["base_start"]
        assert w["text"] and w["episode_steps"] == list(range(w["start"], w["stop"]))

    # the base route: accepted, and the session is complete
    end = page.drive(+1)
    assert end["counted"] and end["counts"]["accepted"] == 1
    assert page.until(lambda m: m["type"] == "review")["verdict"] == "accepted"
    done = page.state_where(state="done")
    assert [h["verdict"] for h in done["history"]] == ["practice", "rejected", "accepted"]
    demos = read_demos(tmp_path / "sessions" / "alice" / "demos.parquet")
    assert demos.n_episodes == 1 and len(demos.obs) == end["length"]
    page.ws.__exit__(None, None, None)


BAD_FIRST_MESSAGES = [
    ("not json", CLOSE_POLICY, "not valid JSON"),
    ('{"type": "hello", "name": "../x"}', CLOSE_POLICY, "operator name"),
    ('{"type": "hello"}', CLOSE_POLICY, "lacks field"),
    ('{"type": "hello", "name": "a", "extra": 1}', CLOSE_POLICY, "unknown field"),
    ('{"type": "start"}', CLOSE_POLICY, "first message must be 'hello'"),
    ('{"type": "shutdown"}', CLOSE_POLICY, "unknown message type"),
    ("[1, 2]", CLOSE_POLICY, "JSON object"),
    ('{"type": "ping", "t": NaN}', CLOSE_POLICY, "NaN"),
    ("x" * (MAX_MESSAGE_BYTES + 1), CLOSE_TOO_BIG, "longer than"),
    (b"\x01\x02", CLOSE_UNSUPPORTED, "binary"),
]


@pytest.mark.parametrize(("payload", "code", "reason"), BAD_FIRST_MESSAGES)
def test_a_malformed_first_message_closes_with_a_reason(make_client, payload, code, reason):
    client = make_client()
    with client.websocket_connect("/ws") as ws:
        page = Page(ws)
        if isinstance(payload, bytes):
            ws.send_bytes(payload)
        else:
            ws.send_text(payload)
        msg = page.receive()
        assert msg["type"] == "close" and msg["code"] == code and reason in msg["reason"]


def test_a_malformed_message_closes_only_that_connection(make_client):
    client = make_client()
    alice = _join(client, "alice")
    for bad in (
        {"type": "action", "a": [0.5] * 6},  # wrong length
        {"type": "action", "a": [2, 0, 0, 0, 0, 0, 0]},  # out of range
        {"type": "action", "a": [True, 0, 0, 0, 0, 0, 0]},  # not a number
        {"type": "control", "operator": "yes"},
        {"type": "hello", "name": "bob"},  # twice
    ):
        bob = _join(client, "bob")
        bob.ws.send_text(json.dumps(bad))
        closed = bob.until(lambda m: m["type"] == "close")
        assert closed["code"] == CLOSE_POLICY, bad
    flood = _join(client, "bob")
    for _ in range(400):
        flood.send(type="ping", t=0)
    closed = flood.until(lambda m: m["type"] == "close")
    assert closed["code"] == CLOSE_POLICY and "too many messages" in closed["reason"]
    alice.send(type="ping", t=7)  # alice never noticed
    assert alice.until(lambda m: m["type"] in ("pong", "close")) == {"type": "pong", "t": 7}
    alice.ws.__exit__(None, None, None)


def test_reload_reattaches_and_a_second_window_takes_over(make_client):
    client = make_client()
    first = _join(client, "carol")
    first.send(type="action", a=[1, 0, 0, 0, 0, 0, -1])
    first.send(type="start")
    first.until(lambda m: m["type"] == "frame" and m["step"] >= 5)
    second = _join(client, "carol")  # a reload: the same operator again
    assert first.until(lambda m: m["type"] == "close")["code"] == CLOSE_REPLACED
    state = second.state
    assert state["state"] == "ready" and state["episode"] == 0 and state["step"] >= 5  # paused
    frame = next(f for f in reversed(second.frames) if f["episode"] == 0)
    assert frame["step"] == state["step"]  # the page redraws where the episode stands
    second.send(type="start")  # and continues the same episode
    second.until(lambda m: m["type"] == "frame" and m["step"] == state["step"] + 1)
    second.ws.__exit__(None, None, None)


def test_a_server_restart_resumes_every_operator(make_client, tmp_path):
    root = tmp_path / "shared"
    first = make_client(root=root)
    pages = {name: _join(first, name) for name in ("dana", "eli")}
    ended = pages["dana"].drive(+1, give_up_after=5)  # dana gives up her practice episode
    assert ended["gave_up"] and not ended["success"]  # not the same as running out of time
    pages["eli"].send(type="action", a=[1, 0, 0, 0, 0, 0, -1])
    pages["eli"].send(type="start")  # eli is mid-episode when the server stops
    pages["eli"].until(lambda m: m["type"] == "frame" and m["step"] >= 3)
    for p in pages.values():
        p.ws.__exit__(None, None, None)
    first.app.state.hub.shutdown()

    second = make_client(root=root)
    dana, eli = _join(second, "dana"), _join(second, "eli")
    assert next(m for m in dana.texts if m["type"] == "welcome")["resumed"]
    assert (dana.state["episode"], dana.state["episode_kind"]) == (1, "demonstration")
    assert dana.state["counts"]["practice"] == 1 and dana.state["prompt_pending"]
    assert (eli.state["episode"], eli.state["step"]) == (0, 0)  # the cut episode starts again
    assert [h["verdict"] for h in SessionStore(root / "dana").episode_headers()] == ["practice"]
    assert SessionStore(root / "eli").episode_headers() == []
    for p in (dana, eli):
        p.ws.__exit__(None, None, None)


def test_naive_mode_hides_prompt_indicator_and_verdict(make_client):
    client = make_client(mode="naive", practice=0)
    page = _join(client, "nia")
    welcome = next(m for m in page.texts if m["type"] == "welcome")
    assert welcome["rule"] == "" and welcome["prompt"] == 0
    end = page.drive(-1)  # the conflicting route: recorded anyway, nothing said about it
    assert end["counted"]
    page.state_where(state="done")
    kinds = {m["type"] for m in page.texts} | {
        e["event"]["kind"] for e in page.texts if e["type"] == "event"
    }
    assert not kinds & {"prompt", "review", "indicator", "indicators"}
    assert all(np.isnan(f["m"]) for f in page.frames)
    page.ws.__exit__(None, None, None)


def test_the_token_guards_every_request_off_loopback(make_client):
    from starlette.websockets import WebSocketDisconnect

    client = make_client(token="s3cret-token")
    assert client.get("/").status_code == 403
    assert client.get("/static/app.js").status_code == 403
    r = client.get("/?token=s3cret-token")
    assert r.status_code == 200 and "elicit_jax_token_8765=s3cret-token" in r.headers["set-cookie"]
    assert client.get("/static/app.js").status_code == 200  # the cookie carries it now
    client.cookies.clear()
    with pytest.raises(WebSocketDisconnect), client.websocket_connect("/ws"):
        pass
    with client.websocket_connect("/ws?token=s3cret-token") as ws:  # past the guard
        ws.send_text('{"type": "ping", "t": 1}')
        assert "must be 'hello'" in Page(ws).receive()["reason"]
    with (
        pytest.raises(WebSocketDisconnect),
        client.websocket_connect(
            "/ws?token=s3cret-token", headers={"origin": "http://evil.example"}
        ),
    ):
        pass


def test_a_full_server_releases_the_operator_who_left_longest_ago(make_client):
    client = make_client(max_operators=1)
    fay = _join(client, "fay")
    with client.websocket_connect("/ws") as ws:
        gil = Page(ws)
        gil.send(type="hello", name="gil")
        closed = gil.until(lambda m: m["type"] == "close")
        assert closed["code"] == CLOSE_FULL and "full" in closed["reason"]
    fay.ws.__exit__(None, None, None)  # fay leaves: her place goes to gil
    time.sleep(0.2)
    gil = _join(client, "gil")
    assert gil.state["state"] == "ready"
    hub = client.app.state.hub
    assert sorted(hub.drivers) == ["gil"]
    gil.ws.__exit__(None, None, None)
