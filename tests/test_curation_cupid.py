"""CUPID: a planted harmful demonstration must rank worst, from scored noisy rollouts."""

import numpy as np
import pytest
from fixtures_data import tiny_train_config

from elicit_jax.curation.cupid import CupidConfig, cupid_scores
from elicit_jax.curation.episodes import OwnRule, select_drop
from elicit_jax.data.demos import from_episodes
from elicit_jax.sim.trajectories import Trajectories

W = np.array([[0.8, -0.3], [0.2, 0.7], [-0.5, 0.4]])


def expert(obs):
    return np.tanh(obs @ W)


def planted_demos(n_good=8, t=20):
    """``n_good`` demos of the expert and one (the last) doing the opposite in the same
    kind of states."""
    rng = np.random.default_rng(0)
    eps = []
    for i in range(n_good + 1):
        obs = rng.normal(size=(t, 3))
        act = expert(obs) * (-1.0 if i == n_good else 1.0)
        eps.append({"obs": obs, "action": act})
    return from_episodes(eps, operators="op")


def noisy_rollouts(policy, m=120, t=4, noise=0.2):
    """Rollouts of a toy task: the policy's action plus noise; a rollout succeeds when its
    noise, summed over its steps, points towards the expert's actions."""
    import jax.numpy as jnp

    rng = np.random.default_rng(1)
    obs = rng.normal(size=(m * t, 3)).astype(np.float32)
    mean = np.asarray(jnp.mean(policy.members(jnp.asarray(obs)), axis=0))
    act = (mean + noise * rng.normal(size=mean.shape)).astype(np.float32)
    gain = ((expert(obs) - mean) * (act - mean)).sum(1)
    rollout = np.repeat(np.arange(m), t)
    success = np.bincount(rollout, weights=gain, minlength=m) > 0
    return Trajectories(obs, act, rollout, success, success.astype(float), noise, {})


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    from elicit_jax.policy.checkpoint import load_policy
    from elicit_jax.policy.train import train_policy

    demos = planted_demos()
    d = tmp_path_factory.mktemp("cupid")
    cfg = tiny_train_config(hidden=(16,), epochs=60, checkpoint_every=60, dropout=0.0)
    train_policy(demos, cfg, d / "run", quiet=True)
    return demos, load_policy(d / "run", "final")


@pytest.mark.parametrize("proj_dim", [512, 48])
def test_planted_harmful_demo_ranks_worst(trained, proj_dim):
    demos, policy = trained
    steps = noisy_rollouts(policy)
    assert 0 < steps.success.sum() < len(steps.success)
    scores = cupid_scores(policy, steps, demos, None, CupidConfig(proj_dim=proj_dim))
    assert scores.trusted
    assert scores.report["projected"] == (proj_dim == 48)
    assert int(np.argmin(scores.score)) == 8
    assert scores.score[8] < 0 < np.min(scores.score[:8])
    drop, _ = select_drop(scores, OwnRule())
    assert drop.tolist() == [False] * 8 + [True]


def test_deterministic_rollouts_have_no_signal(trained):
    import dataclasses

    demos, policy = trained
    steps = dataclasses.replace(noisy_rollouts(policy, noise=0.0), action_noise=0.0)
    scores = cupid_scores(policy, steps, demos, None, CupidConfig())
    assert not scores.trusted and "no exploration noise" in scores.report["why"]
    assert not select_drop(scores, OwnRule())[0].any()
