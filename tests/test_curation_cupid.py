"""CUPID: a planted harmful demonstration must rank worst, from scored noisy rollouts."""

import numpy as np
import pytest
from fixtures_data import tiny_train_config

from elicit_jax.curation.cupid import CupidConfig, cupid_scores
from elicit_jax.curation.episodes import MatchedRule, OwnRule, select_drop
from elicit_jax.data.demos import from_episodes, read_demos
from elicit_jax.sim.trajectories import Trajectories

W = np.random.default_rng(5).normal(0, 0.3, (23, 7))


def expert(obs):
    return np.tanh(obs @ W)


def planted_demos(n_good=8, t=20):
    """``n_good`` demos of the expert and one (the last) doing the opposite in the same
    kind of states."""
    rng = np.random.default_rng(0)
    eps = []
    for i in range(n_good + 1):
        obs = rng.normal(size=(t, 23))
        act = expert(obs) * (-1.0 if i == n_good else 1.0)
        eps.append({"obs": obs, "action": act})
    return from_episodes(eps, operators="op")


def noisy_rollouts(policy, m=120, t=4, noise=0.2):
    """Rollouts of a toy task: the policy's action plus noise; a rollout succeeds when its
    noise, summed over its steps, points towards the expert's actions."""
    import jax.numpy as jnp

    rng = np.random.default_rng(1)
    obs = rng.normal(size=(m * t, 23)).astype(np.float32)
    mean = np.asarray(jnp.mean(policy.members(jnp.asarray(obs)), axis=0))
    act = (mean + noise * rng.normal(size=mean.shape)).astype(np.float32)
    gain = ((expert(obs) - mean) * (act - mean)).sum(1)
    rollout = np.repeat(np.arange(m), t)
    success = np.bincount(rollout, weights=gain, minlength=m) > 0
    return Trajectories(obs, act, rollout, success, success.astype(float), noise, {})


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.policy.train import train_policy

    demos = planted_demos()
    d = tmp_path_factory.mktemp("cupid")
    cfg = tiny_train_config(hidden=(16,), epochs=60, checkpoint_every=60, dropout=0.0)
    train_policy(demos, cfg, d / "run", quiet=True)
    return demos, load_policy(d / "run", "final").policy, d


def test_planted_harmful_demo_ranks_worst(trained):
    demos, policy, _ = trained
    steps = noisy_rollouts(policy)
    assert 0 < steps.success.sum() < len(steps.success)
    scores = cupid_scores(policy, steps, demos, None, CupidConfig(proj_dim=256))
    assert scores.trusted and scores.report["projected"]  # 535 parameters per member
    assert int(np.argmin(scores.score)) == 8
    assert scores.score[8] < 0 < np.median(scores.score[:8])
    assert select_drop(scores, OwnRule())[0][8]  # own cut: negative influence
    drop, _ = select_drop(scores, MatchedRule(episodes=1))
    assert drop.tolist() == [False] * 8 + [True]


def test_deterministic_rollouts_have_no_signal(trained):
    import dataclasses

    demos, policy, _ = trained
    steps = dataclasses.replace(noisy_rollouts(policy, noise=0.0), action_noise=0.0)
    scores = cupid_scores(policy, steps, demos, None, CupidConfig())
    assert not scores.trusted and "no exploration noise" in scores.report["why"]
    assert not select_drop(scores, OwnRule())[0].any()


def test_rollouts_of_one_outcome_have_no_signal(trained):
    """All successes (or all failures): the return does not vary, REINFORCE's estimate has
    mean zero, and the scores are marked untrusted instead of dropping demos on noise."""
    import dataclasses

    demos, policy, _ = trained
    steps = noisy_rollouts(policy)
    for outcome, word in ((True, "succeeded"), (False, "failed")):
        same = dataclasses.replace(steps, success=np.full_like(steps.success, outcome))
        scores = cupid_scores(policy, same, demos, None, CupidConfig())
        assert not scores.trusted and f"all 120 rollouts {word}" in scores.report["why"]
        assert not select_drop(scores, OwnRule())[0].any()


def test_cli_evaluate_trajectories_then_filter_cupid(trained, tmp_path):
    """evaluate --trajectories records noisy steps on C MuJoCo (same noise on a rerun); filter
    --method cupid scores every D_new demo against them and writes its own cut."""
    import pyarrow.parquet as pq
    from typer.testing import CliRunner

    from elicit_jax.cli import app
    from elicit_jax.curation.episodes import read_episode_scores
    from elicit_jax.data.demos import write_demos
    from elicit_jax.sim.trajectories import read_trajectories

    demos, _, d = trained
    write_demos(tmp_path / "new.parquet", demos)

    def run(*args):
        return CliRunner().invoke(app, [str(a) for a in args])

    # the planted demos record no task: the task is named (evaluate no longer assumes one)
    ev = ["evaluate", "--policy", d / "run", "--task", "square-nut", "--rollouts", 3,
          "--horizon", 4, "--backend", "mujoco", "--checkpoint", "final",
          "--action-noise", 0.3]  # fmt: skip
    for name in ("a", "b"):
        r = run(*ev, "--trajectories", tmp_path / f"{name}.parquet")
        assert r.exit_code == 0, (r.output, r.exception)
    steps = read_trajectories(tmp_path / "a.parquet")
    assert steps.obs.shape == (12, 23) and steps.action.shape == (12, 7)
    assert steps.action_noise == 0.3 and len(steps.success) == 3
    a, b = (pq.read_table(tmp_path / f"{n}.parquet").to_pandas() for n in "ab")
    np.testing.assert_array_equal(np.stack(a["action"]), np.stack(b["action"]))
    r = run("filter", "--method", "cupid", "--demos", tmp_path / "new.parquet",
            "--policy", d / "run", "-o", tmp_path / "kept.parquet")  # fmt: skip
    assert r.exit_code != 0 and "--trajectories" in str(r.exception)
    r = run("filter", "--method", "cupid", "--demos", tmp_path / "new.parquet",
            "--policy", d / "run", "--trajectories", tmp_path / "a.parquet",
            "-o", tmp_path / "kept.parquet")  # fmt: skip
    assert r.exit_code != 0 and "it has seed 0 checkpoint final" in str(r.exception)
    assert not (tmp_path / "kept.parquet").exists()
    r = run("filter", "--method", "cupid", "--demos", tmp_path / "new.parquet",
            "--policy", d / "run", "--trajectories", tmp_path / "a.parquet",
            "--checkpoint", "final", "-o", tmp_path / "kept.parquet")  # fmt: skip
    assert r.exit_code == 0, (r.output, r.exception)
    scores = read_episode_scores(tmp_path / "kept.episode-scores.parquet")
    assert scores.method == "cupid" and len(scores.score) == 9
    # 3 rollouts of 4 steps cannot reach the goal: every return is the same, so no signal
    assert not scores.trusted and "all 3 rollouts failed" in scores.report["why"]
    assert "warning: cupid had no signal" in r.output
    assert read_demos(tmp_path / "kept.parquet").n_episodes == 9  # nothing dropped on noise
    mjx = [a if a != "mujoco" else "mjx" for a in ev]
    r = run(*mjx, "--trajectories", tmp_path / "c.parquet")
    assert r.exit_code != 0 and "C MuJoCo" in str(r.exception)


def test_pipeline_stages_write_episode_scores(trained, tmp_path):
    """The pipeline's cupid stage (noisy rollouts of the naive run, then scores) and quality
    stage write per-demonstration scores the curate stage reads."""
    import types

    from rich.console import Console

    from elicit_jax.curation.episodes import read_episode_scores
    from elicit_jax.data.demos import write_demos
    from elicit_jax.pipeline.curation_stages import (
        cupid_stage,
        quality_stage,
        resolve_cupid,
        resolve_quality,
    )

    demos, _, d = trained
    write_demos(tmp_path / "new.parquet", demos)
    raw = {"task": "reach-pillar", "model": "mlp", "operator": "op", "rollouts": 2,
           "checkpoint": "final", "proj_dim": 64}  # fmt: skip
    new = tmp_path / "new.parquet"
    ctx = types.SimpleNamespace(
        config=resolve_cupid(raw),
        inputs={"policy": d / "run", "demos0": new, "demos1": new},
        output=tmp_path / "cupid.parquet",
        console=Console(quiet=True),
    )
    cupid_stage(ctx)
    scores = read_episode_scores(ctx.output)
    assert scores.method == "cupid" and len(scores.score) == 9
    assert scores.report["rollouts"] == 2 and scores.report["action_noise"] == 0.1
    ctx.config = resolve_quality({"task": "reach-pillar", "operator": "op"})
    ctx.output = tmp_path / "quality.parquet"
    quality_stage(ctx)
    q = read_episode_scores(ctx.output)
    assert q.method == "quality" and q.threshold == -3.5 and len(q.score) == 9
