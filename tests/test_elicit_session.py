"""Elicitation sessions on square-nut: the protocol end to end with scripted operators.

The base policy is tiny (3 x 64-64, 40 epochs on 10 base demos) and the thresholds are
fitted, with the library's own ``fit_thresholds``, on 3 same-style and 3
conflict-flip-pause demonstrations collected from other initial states than the sessions'
— so the tests depend on the operators only through "same style is compatible, the
conflicting style is not", not on their exact motions.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from fixtures_data import SessionInputs

from elicit_jax.elicit.events import (
    IndicatorEvent,
    PromptEvent,
    ReviewEvent,
    SessionEndEvent,
)
from elicit_jax.elicit.run import run_session
from elicit_jax.elicit.setup import open_session
from elicit_jax.elicit.store import SessionStore
from elicit_jax.errors import ElicitError


@pytest.fixture(scope="module")
def nut(square_nut_session_inputs) -> SessionInputs:
    """D_base, base policy and (λ, η) of square-nut, shared with the other session tests."""
    return square_nut_session_inputs


class Recorder:
    """Wraps an operator and keeps every event it is sent."""

    def __init__(self, inner):
        self.inner, self.name, self.events = inner, inner.name, []

    def on_event(self, event):
        self.events.append(event)
        self.inner.on_event(event)

    def act(self, observation):
        return self.inner.act(observation)

    def of(self, kind):
        return [e for e in self.events if isinstance(e, kind)]


def _run(nut: SessionInputs, out: Path, operator: str, **kw):
    setup, op, _ = open_session(nut.session_config(operator, **kw), out)
    rec = Recorder(op)
    return run_session(setup, rec), rec


def _live_by_episode(rec):
    """The live states of each demonstration's indicator events, by episode."""
    from elicit_jax.elicit.events import EpisodeStartEvent

    out, current = {}, None
    for e in rec.events:
        if isinstance(e, EpisodeStartEvent):
            current = e.episode
        elif isinstance(e, IndicatorEvent):
            out.setdefault(current, []).append(e.live)
    return out


def _check_live_agrees_with_verdicts(rec, reviews, horizon):
    """At every step the live state agrees with the episode's final verdict."""
    lives = _live_by_episode(rec)
    for review in reviews:
        states = lives[review.episode]
        assert {s.allowed for s in states} == {int(0.05 * horizon)}  # fixed by the horizon
        assert [s.red for s in states] == sorted(s.red for s in states)
        doomed = [s.doomed for s in states]
        assert doomed == sorted(doomed)  # once it can no longer be accepted, it never can
        if any(doomed):
            assert review.verdict == "rejected"
        assert states[-1].accept_now == (review.verdict == "accepted")
        assert (states[-1].red, states[-1].scored) == (review.incompatible, review.scored)
    return lives


def _yaw(q):
    from elicit_jax.sim.env import quat_yaw

    return quat_yaw(np.asarray(q, np.float64))


def test_informed_conflicting_operator_is_rejected_where_its_style_differs(nut, tmp_path):
    from elicit_jax.data.demos import read_demos

    session, rec = _run(nut, tmp_path / "op4", "scripted:conflict-flip-pause", max_episodes=3)
    c = session.progress.counts
    assert (c.practice, c.accepted, c.rejected, c.episodes) == (1, 0, 2, 3)
    assert session.end_reason == "max-episodes"
    assert len(rec.of(PromptEvent)) == 1 and len(rec.of(PromptEvent)[0].episodes) == 2
    reviews = rec.of(ReviewEvent)
    assert [r.verdict for r in reviews] == ["rejected", "rejected"]
    store = SessionStore(tmp_path / "op4")
    base = read_demos(nut.base)
    rows = {e: (s, t) for e, s, t in base.episode_bounds()}
    for review in reviews:
        ep = store.read_episode(review.episode)
        assert len(review.feedback) == 3 and review.text.startswith("rejected")
        # one indicator event per scored step of the demonstration
        n_ind = sum(1 for e in rec.events if isinstance(e, IndicatorEvent))
        assert n_ind >= ep.length
        for fb in review.feedback:
            win = slice(fb.start, fb.stop)
            paused = np.all(ep.action[win, :6] == 0.0, axis=1).mean() >= 0.5
            s0 = rows[fb.base_episode][0]
            seg = base.obs[s0 + fb.base_start : s0 + fb.base_stop]
            yaw_gap = np.abs(
                np.angle(np.exp(1j * (_yaw(ep.obs[win, 3:7]).mean() - _yaw(seg[:, 3:7]).mean())))
            )
            turning = np.abs(ep.action[win, 5]).mean() > 0.5
            # each flagged window is a pause or the wrist's half turn (turning, or turned)
            assert paused or turning or yaw_gap > np.pi / 2, fb.text
            if paused:
                assert fb.motion == "still" and "hold still where the base moves" in fb.text
            else:
                names = [d.name for d in fb.fields[:2]] + [fb.actions[0].name]
                assert "robot0_eef_quat" in names or "dyaw" in names, fb.text
    assert not store.demos_path.exists()  # nothing accepted
    lives = _check_live_agrees_with_verdicts(rec, reviews, session.setup.task.config.horizon)
    lights = {s.light for states in lives.values() for s in states}
    assert {"red", "idle"} <= lights  # its pauses read as idle, never as green


def test_informed_same_style_is_accepted_into_a_collect_schema_demos_file(nut, tmp_path):
    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.compat.score import score_demos
    from elicit_jax.data.demos import CORE_COLUMNS, read_demos
    from elicit_jax.elicit.replay import replay_episode
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.sim.env import make_task

    session, rec = _run(nut, tmp_path / "op1", "scripted:same-style")
    c = session.progress.counts
    assert (c.accepted, c.rejected, session.end_reason) == (2, 0, "complete")
    assert [r.verdict for r in rec.of(ReviewEvent)] == ["accepted", "accepted"]
    _check_live_agrees_with_verdicts(rec, rec.of(ReviewEvent), session.setup.task.config.horizon)
    assert rec.of(SessionEndEvent)[0].reason == "complete"
    demos = read_demos(tmp_path / "op1" / "demos.parquet")
    collected = read_demos(nut.base)
    assert demos.n_episodes == 2 and set(demos.operator) == {"same-style"}
    assert demos.obs_fields == collected.obs_fields and demos.task == collected.task
    assert {"init_seed", "session_episode", "source_step"} <= set(demos.extra)
    assert set(CORE_COLUMNS) and demos.success.all()
    score_demos(
        load_policy(nut.policy).policy, demos, ScoreConfig.from_preset("square-nut")
    )  # score takes it as is
    store = SessionStore(tmp_path / "op1")
    ep = store.read_episode(int(demos.extra["session_episode"][0]))
    np.testing.assert_array_equal(demos.obs[: ep.length], ep.obs)
    replay = replay_episode(make_task("square-nut"), ep)
    np.testing.assert_array_equal(replay["qpos"], ep.qpos)  # exact replay
    np.testing.assert_array_equal(replay["qvel"], ep.qvel)
    assert bool(replay["success"])


def test_naive_mode_accepts_completed_demos_and_only_records_the_rule(nut, tmp_path):
    session, rec = _run(nut, tmp_path / "naive", "scripted:conflict-flip-pause", mode="naive")
    assert session.progress.counts.accepted == 2
    assert not rec.of(ReviewEvent) and not rec.of(IndicatorEvent) and not rec.of(PromptEvent)
    store = SessionStore(tmp_path / "naive")
    heads = [h for h in store.episode_headers() if h["episode_kind"] == "demonstration"]
    assert [h["rule_verdict"] for h in heads] == ["reject", "reject"]
    assert [h["verdict"] for h in heads] == ["accepted", "accepted"]
    assert all(h["feedback"] and not h["feedback_shown"] for h in heads)


def test_dagger_stores_only_the_operators_interventions(nut, tmp_path):
    from elicit_jax.data.demos import read_demos

    session, _ = _run(
        nut, tmp_path / "dag", "scripted:base", dagger=True, practice=0, demos=1, max_episodes=3
    )
    store = SessionStore(tmp_path / "dag")
    eps = [store.read_episode(int(p.stem[1:])) for p in store.episode_files()]
    rates = [ep.operator.mean() for ep in eps]
    assert all(0 < r < 1 for r in rates), rates  # the robot acted and the operator took over
    assert all(ep.meta["interventions"] >= 1 for ep in eps)
    for ep in eps:  # only the operator's steps are scored
        assert np.isfinite(ep.compatibility[ep.operator]).all()
        assert np.isnan(ep.compatibility[~ep.operator]).all()
    rows = [r for r in session.progress.rows if r["intervention_rate"] is not None]
    assert len(rows) == len(eps)
    if store.demos_path.exists():
        demos = read_demos(store.demos_path)
        assert demos.extra["intervention"].all()
        for e in np.unique(demos.extra["session_episode"]):
            ep = store.read_episode(int(e))
            sel = demos.extra["session_episode"] == e
            steps = demos.extra["source_step"][sel]
            assert ep.operator[steps].all() and sel.sum() == ep.operator.sum()
            np.testing.assert_array_equal(demos.obs[sel], ep.obs[steps])


def test_retraining_between_batches(nut, tmp_path):
    from elicit_jax.artifact import read_header

    session, rec = _run(nut, tmp_path / "b", "scripted:same-style", practice=0, batch=1)
    heads = SessionStore(tmp_path / "b").episode_headers()
    assert [h["policy_batch"] for h in heads] == [0, 1]  # the 2nd demo is scored by π_1
    assert session.setup.scorer.traces == 1  # π_1 scored with the same compiled function
    assert [h["batch"] for h in heads] == [1, 2]
    for b in (1, 2):
        run = read_header(tmp_path / "b" / "policies" / f"batch{b}")
        base = read_header(nut.policy)
        assert run["config"]["epochs"] == base["config"]["epochs"]  # the base's config
        seed = read_header(tmp_path / "b" / "policies" / f"batch{b}" / "seed0")
        assert len(seed["train_episodes"]) + len(seed["val_episodes"]) == 10 + b
    assert [e.status for e in rec.events if type(e).__name__ == "RetrainEvent"] == [
        "start",
        "done",
        "start",
        "done",
    ]
    # killed while training batch 2 (an atomic directory write: no half policy) -> resume trains it
    shutil.rmtree(tmp_path / "b" / "policies" / "batch2")
    _, rec = _run(nut, tmp_path / "b", "scripted:same-style", practice=0, batch=1)
    assert [(e.batch, e.status) for e in rec.events if type(e).__name__ == "RetrainEvent"] == [
        (2, "start"),
        (2, "done"),
    ]
    assert (tmp_path / "b" / "policies" / "batch2" / "artifact.json").exists()
    _run(nut, tmp_path / "f", "scripted:same-style", practice=0, batch=1, fixed_base=True, demos=2)
    heads = SessionStore(tmp_path / "f").episode_headers()
    assert [h["policy_batch"] for h in heads] == [0, 0]


def _cli(*args: str, **kw) -> subprocess.Popen:
    code = "from elicit_jax.cli import main; main()"
    return subprocess.Popen(
        [sys.executable, "-c", code, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kw,
    )


def _same_episodes(a: SessionStore, b: SessionStore) -> list[dict]:
    """Assert two sessions recorded the same episodes (seeds, verdicts, actions)."""
    ha, hb = a.episode_headers(), b.episode_headers()
    assert [h["index"] for h in ha] == list(range(len(ha)))  # nothing lost, nothing twice
    key = ("index", "episode_kind", "init_seed", "operator_seed", "verdict", "length")
    assert [[h[k] for k in key] for h in ha] == [[h[k] for k in key] for h in hb]
    for h in ha:  # same actions: the operator's randomness resumed exactly
        np.testing.assert_array_equal(
            a.read_episode(h["index"]).action, b.read_episode(h["index"]).action
        )
    return ha


class Crash(Exception):
    pass


class CrashingOperator(Recorder):
    """Dies at step ``at`` of episode ``episode`` (like a kill in the middle of it)."""

    def __init__(self, inner, episode, at):
        super().__init__(inner)
        self.episode, self.at = episode, at

    def act(self, observation):
        if (observation.episode, observation.step) == (self.episode, self.at):
            raise Crash
        return self.inner.act(observation)


def test_a_crash_mid_episode_loses_only_that_episode(nut, tmp_path):
    from elicit_jax.data.demos import read_demos

    kw = dict(mode="naive", demos=2, practice=1)
    setup, op, _ = open_session(
        nut.session_config("scripted:conflict-flip-pause", **kw), tmp_path / "c"
    )
    with pytest.raises(Crash):
        run_session(setup, CrashingOperator(op, episode=2, at=150))
    assert [p.name for p in SessionStore(tmp_path / "c").episode_files()] == [
        "e000000.parquet",
        "e000001.parquet",
    ]
    session, _ = _run(nut, tmp_path / "c", "scripted:conflict-flip-pause", **kw)  # resumes
    _run(nut, tmp_path / "ref", "scripted:conflict-flip-pause", **kw)
    _same_episodes(SessionStore(tmp_path / "c"), SessionStore(tmp_path / "ref"))
    assert session.progress.counts.accepted == 2
    assert read_demos(tmp_path / "c" / "demos.parquet").n_episodes == 2


def test_kill_9_mid_session_and_resume_loses_only_the_episode_in_progress(nut, tmp_path):
    from elicit_jax.data.demos import read_demos

    out = tmp_path / "killed"
    args = [
        "elicit",
        "--task",
        "square-nut",
        "--policy",
        str(nut.policy),
        "--base-demos",
        str(nut.base),
        "--lambda",
        str(nut.lam),
        "--eta",
        str(nut.eta),
        "--operator",
        "scripted:conflict-flip-pause",
        "--mode",
        "naive",
        "--demos",
        "3",
        "--practice",
        "1",
        "-o",
        str(out),
    ]
    proc = _cli(*args)
    deadline = time.monotonic() + 120
    while len(list((out / "episodes").glob("e*.parquet"))) < 2:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.01)
    time.sleep(0.15)  # into the next episode (about 0.5 s long)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert 2 <= len(list((out / "episodes").glob("e*.parquet"))) <= 3
    again = _cli(*args)
    stdout, stderr = again.communicate(timeout=180)
    assert again.returncode == 0, stderr
    assert "resuming the session" in stdout
    _run(
        nut,
        tmp_path / "ref",
        "scripted:conflict-flip-pause",
        mode="naive",
        demos=3,
        practice=1,
        max_episodes=0,
    )
    _same_episodes(SessionStore(out), SessionStore(tmp_path / "ref"))
    demos = read_demos(out / "demos.parquet")
    assert demos.n_episodes == 3 and len(set(demos.extra["session_episode"])) == 3
    assert not list(out.rglob(".*.tmp"))


def test_cli_bad_inputs_info_and_report(nut, tmp_path, cli):
    from elicit_jax.data.demos import from_episodes, write_demos

    head = ["elicit", "--task", "square-nut", "--policy", nut.policy]
    thr = ["--lambda", nut.lam, "--eta", nut.eta, "--practice", "0", "--demos", "1"]
    common = [*head, "--base-demos", nut.base, *thr]
    out = tmp_path / "s"

    def bad(*args, match):
        code, _, err = cli(*args)
        lines = err.strip().splitlines()
        assert code == 1 and len(lines) == 1 and lines[0].startswith("error:"), err
        assert match in lines[0], lines[0]
        return lines[0]

    bad(*common, "--operator", "scripted:nobody", "-o", out, match="no operator 'nobody'")
    bad(*common, "--operator", "robot:arm", "-o", out, match="unknown operator kind 'robot'")
    show = ["--operator", "scripted:base", "--show", "prompt,voice", "-o", out]
    bad(*common, *show, match="--show takes distinct parts among prompt, indicator, feedback")
    bad(
        *head,
        "--base-demos",
        nut.base,
        "--operator",
        "scripted:base",
        "-o",
        out,
        match="missing thresholds",
    )
    bad(
        *head,
        "--base-demos",
        nut.base,
        "--operator",
        "scripted:base",
        "--lambda",
        "-1",
        "--eta",
        "0.1",
        "-o",
        out,
        match="lambda",
    )
    assert not out.exists()  # nothing written for bad input
    small = from_episodes([{"obs": np.zeros((5, 4)), "action": np.zeros((5, 7))}])
    write_demos(tmp_path / "small.parquet", small)
    bad(
        *head,
        "--base-demos",
        tmp_path / "small.parquet",
        *thr,
        "--operator",
        "scripted:base",
        "-o",
        out,
        match="small.parquet",
    )
    other = tmp_path / "other"
    other.mkdir()
    write_demos(other / "x.parquet", small)
    msg = f"{other}: holds no elicitation session (not an elicit-jax artifact (no artifact.json))"
    bad(*common, "--operator", "scripted:base", "-o", other, match=msg)  # its name once
    code, stdout, err = cli(*common, "--operator", "scripted:same-style", "-o", out)
    assert code == 0, err
    bad(
        *common,
        "--operator",
        "scripted:same-style",
        "--mode",
        "naive",
        "-o",
        out,
        match="different settings (mode)",
    )
    bad("elicit", "--resume", "-o", tmp_path / "none", match="no session")
    code, stdout, err = cli("elicit", "--resume", "-o", out)  # already complete: nothing to do
    assert code == 0 and "resuming" in stdout, err
    code, stdout, _ = cli(*common, "--operator", "scripted:same-style", "--overwrite", "-o", out)
    assert code == 0 and "resuming" not in stdout
    code, stdout, _ = cli("info", out)
    assert code == 0 and "done (all demonstrations accepted)" in stdout and "accepted" in stdout
    code, stdout, _ = cli("report", out)
    assert code == 0
    md = (out / "report" / "report.md").read_text()
    page = (out / "report" / "report.html").read_text()
    assert "## Per batch" in md and "| 1 | 1 | 1 | 0 | 0 | 100% |" in md
    assert "data:image/png;base64," in page and "http" not in page.replace("http-equiv", "")
    with pytest.raises(ElicitError, match="choose one of --resume and --overwrite"):
        open_session(nut.session_config("scripted:base"), out, resume=True, overwrite=True)
