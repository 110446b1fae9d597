"""Session building blocks by hand: rules, field feedback, the live scorer, storage, watch."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import jax
import numpy as np
import pytest

from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.data.demos import fields_from_sizes, from_episodes
from elicit_jax.elicit.config import SessionConfig
from elicit_jax.elicit.events import (
    EpisodeStartEvent,
    FieldDifference,
    Observation,
    ReviewEvent,
    WindowFeedback,
    event_to_dict,
)
from elicit_jax.elicit.explain import (
    action_differences,
    explain_episode,
    field_differences,
    motion,
    window_text,
)
from elicit_jax.elicit.live import LiveScorer
from elicit_jax.elicit.operators import InterventionRule, RouteDistance, ScriptedIntervener
from elicit_jax.elicit.report import trend
from elicit_jax.elicit.rules import AcceptRule
from elicit_jax.elicit.store import EpisodeRecord, SessionStore
from elicit_jax.elicit.watch import Settler, candidates
from elicit_jax.errors import ElicitError


def test_accept_rules_by_hand():
    paper = AcceptRule()  # reject when incompatible > 5% of the length
    assert not paper.rejects(5, 100) and paper.rejects(6, 100)
    assert paper.allowed(40) == 2.0 and not paper.rejects(2, 40) and paper.rejects(3, 40)
    code = AcceptRule(count=3)  # the original code: more than N pairs, whatever the length
    assert not code.rejects(3, 10) and code.rejects(4, 10_000) and code.kind == "count"
    assert "more than 3 pairs" in code.describe() and "5%" in paper.describe()
    with pytest.raises(ElicitError):
        AcceptRule(count=-1)
    with pytest.raises(ElicitError):
        AcceptRule(fraction=1.0)


def _yaw_quat(yaw):
    return np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], axis=-1)


def test_field_and_action_differences_by_hand():
    fields = fields_from_sizes([("pos", 3), ("robot0_eef_quat", 4)])
    w = 5
    op = np.zeros((w, 7))
    base = np.zeros((w, 7))
    op[:, 0:3] = [3.0, 4.0, 0.0]  # 5 m away, every step
    op[:, 3:7] = _yaw_quat(np.full(w, np.pi))  # wrist turned half a turn
    base[:, 3:7] = _yaw_quat(np.zeros(w))
    std = np.array([10.0, 10.0, 10.0, 0.1, 0.1, 0.1, 0.1])
    diffs = {d.name: d for d in field_differences(op, base, fields, std)}
    assert diffs["pos"].difference == pytest.approx(5.0) and diffs["pos"].unit == ""
    assert (
        diffs["robot0_eef_quat"].difference == pytest.approx(np.pi)
        and diffs["robot0_eef_quat"].unit == "rad"
    )
    # normalised: pos RMS of (3, 4, 0)/10 = sqrt(25/300); quat (1-0, 0, 0, 1-0)/0.1 per dims:
    # q_op = (0, 0, 0, 1), q_base = (1, 0, 0, 0) -> RMS sqrt((100 + 100)/4)
    assert diffs["pos"].normalized == pytest.approx(np.sqrt(25 / 300))
    assert diffs["robot0_eef_quat"].normalized == pytest.approx(np.sqrt(50))
    ranked = field_differences(op, base, fields, std)
    assert ranked[0].name == "robot0_eef_quat"
    # -q is the same rotation: no difference
    same = field_differences(-base, base, fields, std)
    assert {d.name: d.difference for d in same}["robot0_eef_quat"] == pytest.approx(0.0)
    acts = action_differences(
        np.array([[1.0, 0.0], [1.0, 0.5]]), np.array([[0.0, 0.0], [0.0, 0.0]]), ["dx", "dyaw"]
    )
    assert [(a.name, a.difference) for a in acts] == [("dx", 1.0), ("dyaw", 0.25)]


def test_motion_and_window_text():
    std = np.ones(2)
    moving = np.cumsum(np.ones((6, 2)), axis=0)  # +1 per step in both dims: RMS 1
    assert motion(moving, std) == pytest.approx(1.0) and motion(np.zeros((6, 2)), std) == 0.0
    fb = WindowFeedback(
        start=40,
        stop=50,
        incompatibility=0.9,
        base_episode=3,
        base_start=35,
        base_stop=45,
        distance=1.0,
        fields=(FieldDifference("robot0_eef_quat", "obs", 3.1, 9.0, "rad"),),
        actions=(FieldDifference("dyaw", "action", 0.8, 0.8),),
        operator_motion=0.0,
        base_motion=1.0,
        motion="still",
        text="",
    )
    line = window_text(fb)
    assert "steps 40–49" in line and "robot0_eef_quat differs by ~3.1 rad" in line
    assert "action dyaw differs by ~0.8" in line and "hold still where the base moves" in line
    assert "base demo 3, steps 35–44" in line and "\n" not in line


def test_explain_episode_flags_the_still_window():
    # base: moves along x at 0.1 per step; operator: same start, holds still for steps 10-19
    t = np.arange(30, dtype=np.float64)
    base_obs = np.stack([0.1 * t, np.zeros(30)], axis=1)
    base = from_episodes(
        [{"obs": base_obs, "action": np.full((30, 2), 0.5)}] * 2,
        obs_fields=fields_from_sizes([("x", 1), ("y", 1)]),
    )
    op_obs = base_obs.copy()
    op_obs[10:20] = op_obs[10]
    op_obs[20:] = base_obs[11:21]
    act = np.full((30, 2), 0.5)
    act[10:20] = 0.0
    m = np.ones(30)
    m[10:20] = 0.0
    fbs = explain_episode(m, op_obs, act, base, window=10, k=1)
    assert (fbs[0].start, fbs[0].stop) == (10, 20) and fbs[0].motion == "still"
    assert fbs[0].actions[0].difference == pytest.approx(0.5)


def _policy(kind="mlp", hidden=(16, 16), seed=0):
    from elicit_jax.policy.base import init_policy

    return init_policy(
        jax.random.key(seed), kind=kind, obs_dim=5, action_dim=3, n_members=3, hidden=hidden
    )


@pytest.mark.parametrize(("likelihood", "ddof"), [("ensemble-mean", 0), ("member-average", 1)])
def test_live_scorer_matches_the_batch_scorer_and_compiles_once(likelihood, ddof):
    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.compat.score import score_demos

    rng = np.random.default_rng(0)
    obs = rng.normal(size=(20, 5)).astype(np.float32)
    act = rng.uniform(-1, 1, size=(20, 3)).astype(np.float32)
    demos = from_episodes([{"obs": obs, "action": act}])
    config = ScoreConfig(thresholds=Thresholds(0.3, 0.2, "given"), likelihood=likelihood, ddof=ddof)
    scorer = LiveScorer(config, _policy(seed=0), bounds=(-1.0, 1.0))
    for policy in (_policy(seed=0), _policy(seed=1)):  # a retrained policy: same architecture
        ref = score_demos(policy, demos, config)
        for i in range(20):
            s = scorer.score(policy, obs[i], act[i])
            assert s.likelihood == pytest.approx(ref["likelihood"][i], rel=1e-5, abs=1e-7)
            assert s.novelty == pytest.approx(ref["novelty"][i], rel=1e-5, abs=1e-7)
            assert s.compatibility == pytest.approx(ref["compatibility"][i], abs=1e-6)
            assert s.incompatible == bool(ref["incompatible"][i])
            np.testing.assert_allclose(s.policy_action, ref["prediction"][i], atol=1e-6)
    assert (
        scorer.score(policy, obs[0], act[0], Thresholds(1e-6, 10.0, "given")).compatibility == 0.0
    )
    assert (
        scorer.score(policy, obs[0], act[0], Thresholds(10.0, 1e-6, "given")).compatibility == 1.0
    )
    assert scorer.traces == 1  # policies, steps and thresholds never recompiled


def test_live_scorer_refuses_an_lstm():
    from elicit_jax.elicit.live import check_live_policy

    with pytest.raises(ElicitError, match="feed-forward"):
        check_live_policy(SimpleNamespace(kind="lstm"))
    check_live_policy(SimpleNamespace(kind="mdn"))


def _record(index=0, n=6, scored_from=2):
    rng = np.random.default_rng(index)
    op = np.arange(n) >= scored_from
    nan = np.where(op, 0.0, np.nan)
    return EpisodeRecord(
        index=index,
        kind="demonstration",
        init_seed=7,
        operator_seed=11,
        batch=1,
        policy_batch=0,
        success=True,
        verdict="accepted",
        rule_verdict="accept",
        feedback=(
            WindowFeedback(
                2,
                4,
                0.5,
                1,
                3,
                5,
                0.2,
                (FieldDifference("x", "obs", 1.0, 2.0),),
                (),
                0.1,
                0.2,
                "",
                "steps 2–3",
            ),
        ),
        feedback_shown=True,
        text="accepted",
        obs=rng.normal(size=(n, 4)).astype(np.float32),
        action=rng.uniform(-1, 1, size=(n, 2)).astype(np.float32),
        qpos=rng.normal(size=(n, 3)),
        qvel=rng.normal(size=(n, 2)),
        operator=op,
        likelihood=nan + rng.uniform(size=n),
        novelty=nan + 0.1,
        compatibility=nan + np.linspace(0, 1, n),
        incompatible=op & (np.arange(n) == 2),
        time_s=np.arange(n) * 0.05,
        score_ms=nan + 0.3,
        meta={"interventions": 1, "dagger": True},
    )


def test_episode_record_round_trip_with_nulls(tmp_path):
    import pyarrow.parquet as pq

    store = SessionStore(tmp_path / "s")
    store.create({"kind": "elicit-session", "schema_version": 1, "config": {}})
    rec = _record()
    path = store.write_episode(rec, {})
    back = store.read_episode(0)
    for name in ("obs", "action", "qpos", "qvel", "operator", "incompatible", "time_s"):
        np.testing.assert_array_equal(getattr(back, name), getattr(rec, name))
    for name in ("likelihood", "novelty", "compatibility", "score_ms"):
        np.testing.assert_allclose(getattr(back, name), getattr(rec, name).astype(np.float32))
    assert back.feedback == rec.feedback and back.meta["interventions"] == 1
    table = pq.read_table(path)
    assert table.column("compatibility").null_count == 2  # robot steps: null, never NaN
    assert not np.isnan(table.column("compatibility").drop_null().to_numpy()).any()
    assert back.n_incompatible == 1 and back.n_scored == 4
    with pytest.raises(ElicitError, match="already exists"):
        store.write_episode(rec, {})
    (store.episodes_dir / "e000001.parquet").write_bytes(b"PAR1 cut short")
    with pytest.raises(ElicitError, match=r"e000001\.parquet.*unreadable"):
        store.episode_headers()


def test_events_are_json_ready():
    fb = _record().feedback
    ev = ReviewEvent(3, "rejected", 9, 100, 0.09, "rule", fb, "text")
    d = event_to_dict(ev)
    assert d["kind"] == "review" and d["feedback"][0]["fields"][0]["name"] == "x"
    start = EpisodeStartEvent(0, "practice", np.zeros(3, np.float32), 1, 2, 10, False, False)
    assert json.loads(json.dumps(event_to_dict(start)))["obs"] == [0.0, 0.0, 0.0]


def test_session_config_checks_and_round_trip():
    given = Thresholds(0.4, 0.05, "given")
    base = dict(task="t", policy="p", base_demos="b", thresholds=given, operator="x:y")
    c = SessionConfig(**base)
    assert SessionConfig.from_dict(c.to_dict()) == c
    assert c.episode_limit == 3 + 5 * 10
    moved = SessionConfig(**{**base, "policy": "elsewhere", "demos": 20})
    assert c.differences(moved) == []  # input paths are compared by content; demos may grow
    assert c.differences(SessionConfig(**{**base, "mode": "naive"})) == ["mode"]
    tighter = SessionConfig(**{**base, "thresholds": Thresholds(0.3, 0.05, "given")})
    assert c.differences(tighter) == ["lambda"]
    for bad in (
        {"mode": "nosy"},
        {"demos": 0},
        {"thresholds": (0.4, 0.05)},
        {"operator": "noname"},
        {"reject_count": -2},
        {"retrieval": "cosine"},
    ):
        with pytest.raises(ElicitError):
            SessionConfig(**{**base, **bad})
    for lam, eta in ((0.0, 0.05), (0.4, float("nan"))):
        with pytest.raises(ElicitError):  # a Thresholds value checks itself
            Thresholds(lam, eta, "given")
    for bad in ({"lambda": 0.0}, {"eta": "x"}, {"thresholds": 0.4}, {"lambd": 1.0}):
        with pytest.raises(ElicitError):
            SessionConfig.from_dict({**c.to_dict(), **bad})


# A session header's config as the code before SessionConfig carried a Thresholds value wrote
# it (dumps of SessionConfig(..., lambda_=0.35, eta=0.045, thresholds_file=...).to_dict()).
STORED_CONFIG = """{
 "accept_fraction": 0.05,
 "base_demos": "/data/base.parquet",
 "batch": 5,
 "dagger": false,
 "ddof": 0,
 "demos": 10,
 "eta": 0.045,
 "fixed_base": false,
 "horizon": 0,
 "lambda": 0.35,
 "likelihood": "ensemble-mean",
 "max_episodes": 0,
 "mode": "informed",
 "operator": "scripted:conflict-flip-pause",
 "policy": "/data/runs/base",
 "policy_seed": null,
 "practice": 3,
 "prompt": 5,
 "reject_count": 3,
 "retrieval": "l2",
 "seed": 0,
 "show": [
  "prompt",
  "feedback"
 ],
 "task": "reach-pillar",
 "thresholds_file": "/data/thresholds.json",
 "which": "best",
 "window": 10,
 "windows": 3
}"""


def test_a_stored_session_header_loads_and_is_written_back_the_same():
    from elicit_jax.artifact import dumps

    c = SessionConfig.from_dict(json.loads(STORED_CONFIG))
    t = c.thresholds
    assert (t.lam, t.eta, t.file, t.source) == (
        0.35, 0.045, Path("/data/thresholds.json"), "file /data/thresholds.json"
    )  # fmt: skip
    assert c.score_config().thresholds.pair == (0.35, 0.045)
    assert (c.show, c.batch, c.reject_count) == (("prompt", "feedback"), 5, 3)
    assert dumps(c.to_dict()) == STORED_CONFIG  # new headers keep the layout, byte for byte
    no_file = {**json.loads(STORED_CONFIG), "thresholds_file": None}
    assert SessionConfig.from_dict(no_file).thresholds == Thresholds(0.35, 0.045, "given")
    resolved = Thresholds(0.2, 0.1, "preset x")  # the caller's thresholds replace the stored
    assert SessionConfig.from_dict(no_file, thresholds=resolved).to_dict()["lambda"] == 0.2


def test_trend_by_hand():
    slope, p = trend(np.array([0.5, 0.4, 0.3, 0.2, 0.1, 0.0]))
    assert slope == pytest.approx(-0.1) and p is not None and p < 0.05
    assert trend(np.array([0.3, 0.1]))[1] is None


class _FakeOperator:
    name = "fake"

    def __init__(self):
        self.restarts = 0

    def on_event(self, event):
        pass

    def restart(self, obs):
        self.restarts += 1

    def act(self, observation):
        return np.ones(2)


def test_scripted_intervener_rule():
    base_obs = np.stack([np.linspace(0, 1, 50), np.zeros(50), np.zeros(50)], axis=1)
    base = from_episodes([{"obs": base_obs, "action": np.zeros((50, 2))}])
    route = RouteDistance(base.obs)
    assert route(base_obs[10]) == pytest.approx(0.0, abs=1e-3)
    rule = InterventionRule(stall_steps=5, stall_distance=0.01, route_distance=1.0, hold_steps=3)
    fake = _FakeOperator()
    iv = ScriptedIntervener(fake, base, slice(0, 3), rule)
    iv.on_event(EpisodeStartEvent(0, "demonstration", base_obs[0], 0, 0, 100, True, False))

    def obs(x):
        return Observation(np.array([x, 0.0, 0.0]), 0, 0, "demonstration", dagger=True)

    # the robot moves along the route: no intervention
    assert all(iv.act(obs(x)) is None for x in np.linspace(0, 0.5, 10))
    # then stalls at 0.5 (where it already was): 5 steps without moving 1 cm -> takes over
    decisions = [iv.act(obs(0.5)) for _ in range(5)]
    assert [d is None for d in decisions] == [True] * 4 + [False] and fake.restarts == 1
    # holds control for 3 steps, then hands back on route
    assert [iv.act(obs(0.5)) is None for _ in range(3)] == [False, False, True]
    # off the route (far from every base state): takes over at once
    assert iv.act(obs(9.0)) is not None and fake.restarts == 2


def test_watch_candidates_and_settling(tmp_path):
    inbox = tmp_path / "inbox"
    (inbox / "verdicts").mkdir(parents=True)
    for name in ("a.hdf5", "b.hdf5.part", ".c.hdf5", "d.tmp", "notes.txt", "e.npz"):
        (inbox / name).write_bytes(b"x")
    (inbox / "ds" / "meta").mkdir(parents=True)
    (inbox / "ds" / "meta" / "info.json").write_text("{}")
    (inbox / "plain").mkdir()
    names = [p.name for p in candidates(inbox, inbox / "verdicts")]
    assert names == ["a.hdf5", "ds", "e.npz"]
    s = Settler(settle=2.0)
    f = inbox / "a.hdf5"
    assert s.ready(f, 0.0) is None and s.ready(f, 1.0) is None
    f.write_bytes(b"xy")  # still being written: the clock starts again
    assert s.ready(f, 2.5) is None and s.ready(f, 4.0) is None
    assert s.ready(f, 4.6) is not None
