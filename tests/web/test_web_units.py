"""Pieces of the browser interface without a server: messages, poses, scene, access, files."""

from __future__ import annotations

import hashlib
import math
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from elicit_jax.web.access import from_own_page, is_loopback, same_origin, scope_token
from elicit_jax.web.protocol import (
    CLOSE_POLICY,
    ProtocolError,
    RateLimiter,
    pack_clip,
    pack_frame,
    parse_message,
    unpack,
)

STATIC = Path(__file__).resolve().parents[2] / "elicit_jax" / "web" / "static"


def test_messages_are_parsed_into_their_fields():
    assert parse_message('{"type": "hello", "name": "op_4-b"}', 7).name == "op_4-b"
    a = parse_message('{"type": "action", "a": [1, -1, 0.5, 0, 0, 0, -1]}', 7).action
    assert a == (1.0, -1.0, 0.5, 0.0, 0.0, 0.0, -1.0)
    assert parse_message('{"type": "control", "operator": true}', 7).operator is True
    assert parse_message('{"type": "give-up"}', 7).type == "give-up"
    assert parse_message('{"type": "ping", "t": 3.5}', 7).t == 3.5


@pytest.mark.parametrize(
    "text",
    [
        '{"type": "action", "a": [1, 0, 0, 0, 0, 0, Infinity]}',
        '{"type": "action", "a": [1, 0, 0, 0, 0, 0, 1.0001]}',
        '{"type": "action", "a": "fast"}',
        '{"type": "hello", "name": ""}',
        '{"type": "hello", "name": "a/b"}',
        '{"type": "hello", "name": "' + "a" * 41 + '"}',
        '{"type": "hello", "name": 3}',
        '{"type": "start", "now": true}',
        '{"kind": "start"}',
        "null",
    ],
)
def test_bad_messages_raise_a_policy_close(text):
    with pytest.raises(ProtocolError) as e:
        parse_message(text, 7)
    assert e.value.code == CLOSE_POLICY and e.value.reason


def test_the_rate_limit_allows_bursts_then_the_average_rate():
    limiter = RateLimiter(rate=10, burst=5)
    t = limiter.last
    for _ in range(5):
        limiter.take(t)
    with pytest.raises(ProtocolError, match="too many"):
        limiter.take(t)
    # one token back after 1/rate seconds (1 us more: (t + 0.1) - t can round below 0.1)
    limiter.take(t + 0.100001)
    with pytest.raises(ProtocolError):
        limiter.take(t + 0.100001)


def test_binary_frames_and_clips_round_trip():
    poses = np.arange(5 * 7, dtype=np.float32).reshape(5, 7)
    data = pack_frame(poses, episode=3, step=41, m=0.25, operator=False)
    assert len(data) == 16 + 5 * 7 * 4
    f = unpack(data)
    assert (f["episode"], f["step"], f["m"], f["operator"]) == (3, 41, 0.25, False)
    np.testing.assert_array_equal(f["poses"], poses)
    assert math.isnan(unpack(pack_frame(poses, 0, 0))["m"])
    clip = np.stack([poses, poses + 1])
    c = unpack(pack_clip(clip, role=2, ident=1))
    assert (c["role"], c["id"]) == (2, 1)
    np.testing.assert_array_equal(c["poses"], clip)


def test_the_scene_describes_reach_pillar_geoms_in_their_bodies():
    from elicit_jax.sim.env import make_task
    from elicit_jax.web.scene import scene_description

    task = make_task("reach-pillar")
    d = scene_description(task.mj_model, task.name)
    assert d["bodies"] == ["world", "gripper", "finger_l", "finger_r", "goal"]
    items = {i["name"]: i for i in d["items"]}
    pillar = items["pillar"]  # fromto 0 0 0 -> 0 0 0.14, radius 0.03: half-length 0.07 at z 0.07
    assert pillar["type"] == "capsule" and pillar["body"] == 0
    np.testing.assert_allclose(pillar["size"][:2], [0.03, 0.07])
    np.testing.assert_allclose(pillar["pos"], [0, 0, 0.07], atol=1e-12)
    assert items["palm"]["type"] == "box" and items["palm"]["body"] == 1
    np.testing.assert_allclose(items["palm"]["size"], [0.012, 0.055, 0.01])
    assert items["goal"]["kind"] == "site" and items["goal"]["rgba"][3] == 0.5
    assert items["floor"]["type"] == "plane"


def test_clips_replay_recorded_states_and_actions_alike():
    from elicit_jax.elicit.replay import replay_episode
    from elicit_jax.sim.env import make_task
    from elicit_jax.web.scene import clip_from_actions, clip_from_states

    task = make_task("reach-pillar")
    actions = np.tile(np.array([1, 1, 0, 0, 0, 0, -1], np.float32), (12, 1))

    class Record:
        init_seed, action = 5, actions

    states = replay_episode(task, Record)
    by_actions = clip_from_actions(task, 5, actions)
    by_states = clip_from_states(task, states["qpos"], init_seed=5)
    assert by_actions.shape == (13, task.mj_model.nbody, 7)
    np.testing.assert_allclose(by_actions[:-1], by_states, atol=1e-6)
    gripper = by_actions[:, 1, :3]
    assert gripper[-1, 0] - gripper[0, 0] > 0.05  # it moved forward (about 0.02 m a step)
    goal = by_actions[:, 4, :3]
    np.testing.assert_allclose(goal, np.broadcast_to(goal[0], goal.shape))  # the goal stays put
    np.testing.assert_allclose(goal[0], states["obs"][0, 9:12], atol=1e-6)


@pytest.mark.parametrize(
    ("host", "loopback"),
    [
        ("127.0.0.1", True),
        ("127.3.2.1", True),
        ("::1", True),
        ("localhost", True),
        ("0.0.0.0", False),
        ("192.168.1.5", False),
        ("::", False),
        ("example.org", False),
    ],
)
def test_loopback_hosts(host, loopback):
    assert is_loopback(host) is loopback


def test_tokens_come_from_the_query_or_the_cookie_and_origins_must_match():
    cookie = "elicit_jax_token_8765"
    scope = {"query_string": b"a=1&token=xyz", "headers": []}
    assert scope_token(scope, cookie) == "xyz"
    scope = {"query_string": b"", "headers": [(b"cookie", b"x=1; elicit_jax_token_8765=abc")]}
    assert scope_token(scope, cookie) == "abc"
    assert scope_token(scope, "elicit_jax_token_8766") == ""  # another server's cookie
    assert scope_token({"query_string": b"", "headers": [(b"cookie", b"\x00bad")]}, cookie) == ""
    same = {"headers": [(b"host", b"box:8765"), (b"origin", b"http://box:8765")]}
    other = {"headers": [(b"host", b"box:8765"), (b"origin", b"http://evil.example")]}
    port = {"headers": [(b"host", b"box:8765"), (b"origin", b"http://box:9999")]}
    assert same_origin(same) and not same_origin(other) and not same_origin(port)
    assert same_origin({"headers": [(b"host", b"box:8765")]})  # no Origin: not a browser page
    post = {"type": "http", "method": "POST"}
    assert from_own_page({**post, **same}) and not from_own_page({**post, **port})
    assert from_own_page({"type": "http", "method": "GET", **port})  # same_origin refuses it
    site = {"headers": [(b"host", b"box:8765"), (b"sec-fetch-site", b"same-site")]}
    assert not from_own_page({**post, **site})
    assert from_own_page({**post, "headers": [(b"host", b"box:8765")]})  # not a browser


def test_three_js_is_shipped_unchanged_with_its_licence():
    three = STATIC / "three"
    readme = (three / "README.md").read_text()
    for name in ("three.module.js", "three.core.js"):
        digest = hashlib.sha256((three / name).read_bytes()).hexdigest()
        assert digest in readme, name
    assert (three / "LICENSE").read_text().startswith("The MIT License")
    controls = (three / "OrbitControls.js").read_text()
    assert "from './three.module.js'" in controls and "from 'three'" not in controls


def test_the_page_fetches_nothing_from_elsewhere():
    for path in [*STATIC.glob("*.html"), *STATIC.glob("*.js"), *STATIC.glob("*.css")]:
        text = path.read_text()
        assert not re.search(r"""(src|href)=["']?(https?:)?//""", text), path
        assert not re.search(r"""(import|from)\s*\(?\s*["']https?://""", text), path


def test_serve_refuses_bad_settings_in_one_line():
    from elicit_jax.cli import app

    cases = [
        (["serve", "--demo", "--policy", "p"], "--demo brings its own inputs"),
        (["serve", "--demo", "--task", "square-nut"], "--demo serves reach-pillar"),
        (["serve", "--task", "reach-pillar"], "missing --policy, --base-demos, thresholds"),
        (["serve", "--demo-dir", "x"], "--demo-dir goes with --demo"),
    ]
    for args, message in cases:
        result = CliRunner().invoke(app, args)
        assert result.exit_code != 0 and message in str(result.exception), args


def test_serve_keeps_the_thresholds_whole(monkeypatch, tmp_path):
    """Their source, file and recorded trust verdict reach the sessions (serve took them
    apart into λ and η and rebuilt them, losing the verdict)."""
    from elicit_jax.cli import app, session_options
    from elicit_jax.compat.thresholds import Thresholds, read_thresholds, write_thresholds
    from elicit_jax.web import serve

    t = tmp_path / "t.json"
    given = Thresholds(0.3, 0.07, "given")
    write_thresholds(t, given, method="manual", inputs={}, config={}, report={})
    seen = []
    monkeypatch.setattr(serve, "serve", lambda config, **_: seen.append(config))
    # no real policy here: the recorded-task check (tests/test_task_recorded.py) is not this one
    monkeypatch.setattr(session_options, "recorded_task", lambda given, force: None)
    args = ["serve", "--task", "reach-pillar", "--policy", "p", "--base-demos", "b.parquet"]
    result = CliRunner().invoke(app, [*args, "--thresholds", str(t), "--horizon", "50"])
    assert result.exit_code == 0, (result.output, result.exception)
    kept = seen[0].session.thresholds
    assert kept == read_thresholds(t)
    assert kept.verdict is not None and not kept.verdict.clean and kept.source == f"file {t}"
    assert f"thresholds: λ=0.3, η=0.07 from file {t}" in result.output  # said which


def test_the_demo_cache_key_covers_the_version_and_the_training_config(monkeypatch):
    """An upgrade or a changed training default builds the `serve --demo` inputs anew."""
    import dataclasses

    import elicit_jax
    from elicit_jax.pipeline import serve_demo as demo

    recipe = demo.DemoRecipe()
    key = demo.recipe_hash(recipe)
    assert demo.recipe_hash(recipe) == key  # stable
    with monkeypatch.context() as m:
        m.setattr(elicit_jax, "__version__", elicit_jax.__version__ + ".post1")
        assert demo.recipe_hash(recipe) != key
    trained = demo.train_config
    with monkeypatch.context() as m:
        m.setattr(demo, "train_config", lambda r: dataclasses.replace(trained(r), lr=0.002))
        assert demo.recipe_hash(recipe) != key
    assert demo.recipe_hash(recipe) == key


def test_serve_summary_table_lists_each_operator_served():
    from types import SimpleNamespace

    from rich.console import Console

    from elicit_jax.cli.serve_cmd import summary_table
    from elicit_jax.elicit.events import Counts

    counts = Counts(practice=1, accepted=2, rejected=1, failed=0, episodes=4, wanted=5)
    hub = SimpleNamespace(
        root="sessions",
        drivers={
            "op2": SimpleNamespace(session=None, state="waiting", steps=0),
            "op1": SimpleNamespace(
                session=SimpleNamespace(progress=SimpleNamespace(counts=counts)),
                state="done",
                steps=321,
            ),
        },
    )
    console = Console(record=True, width=120)
    console.print(summary_table(hub))
    rows = [line.split("│") for line in console.export_text().splitlines() if "│ op" in line]
    cells = [[c.strip() for c in row if c.strip()] for row in rows]
    assert cells == [
        ["op1", "done", "2/5", "1", "0", "4", "321"],
        ["op2", "waiting", "-", "-", "-", "-", "0"],
    ]
