"""Policy building blocks with hand-computed values: MDN maths, windows, split, config."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

from elicit_jax.errors import ElicitError
from elicit_jax.policy import models
from elicit_jax.policy.base import normalization_stats
from elicit_jax.policy.checkpoint import flatten_params, unflatten_params
from elicit_jax.policy.config import TrainConfig
from elicit_jax.policy.dataset import make_windows, split_episodes
from elicit_jax.policy.train import chunk_epochs


def test_mdn_std_of_two_point_mixture():
    # Components at 0 and 1 with equal weight and ~zero scale: mean 0.5,
    # E[x^2] = 0.5 * 0 + 0.5 * 1 = 0.5, var = 0.5 - 0.25 = 0.25, std = 0.5.
    logits = jnp.zeros((1, 2))
    means = jnp.array([[[0.0], [1.0]]])
    stds = jnp.full((1, 2, 1), 1e-4)
    np.testing.assert_allclose(models.mdn_std(logits, means, stds), [[0.5]], atol=1e-6)
    # Weights 3:1 (logits log 3, 0): the mode is component 0.
    logits = jnp.array([[math.log(3.0), 0.0]])
    np.testing.assert_allclose(models.mdn_mode(logits, means), [[0.0]])


def test_mdn_log_likelihood_of_standard_normal():
    # One component N(0, 1) in 2 dims at a = 0: log p = 2 * (-0.5 * log(2 pi)) = -1.8379.
    ll = models.mdn_log_likelihood(
        jnp.zeros((1, 1)), jnp.zeros((1, 1, 2)), jnp.ones((1, 1, 2)), jnp.zeros((1, 2))
    )
    np.testing.assert_allclose(ll, [-math.log(2 * math.pi)], rtol=1e-6)


def test_windows_pad_short_episodes():
    # Episode A rows 0..5 (T=6), episode B rows 6..8 (T=3); L=4:
    # A gives starts 0,1,2 (6-4+1 = 3 windows), B one window padded past row 8.
    wins, mask = make_windows([(0, 0, 6), (1, 6, 9)], 4)
    assert wins.tolist() == [[0, 1, 2, 3], [1, 2, 3, 4], [2, 3, 4, 5], [6, 7, 8, 8]]
    assert mask.tolist()[-1] == [1, 1, 1, 0]
    assert mask[:3].min() == 1


def test_split_by_episode_is_deterministic_and_disjoint():
    ids = np.arange(20) * 3
    train, val = split_episodes(ids, 0.1)
    assert len(val) == 2 and len(train) == 18  # round(0.1 * 20) = 2
    assert not set(train) & set(val)
    again = split_episodes(ids, 0.1)
    assert np.array_equal(train, again[0]) and np.array_equal(val, again[1])
    assert len(split_episodes(np.array([7]), 0.5)[1]) == 0  # a single episode is never held out
    assert len(split_episodes(ids, 0.0)[1]) == 0


def test_normalization_guards_constant_dims():
    obs = np.array([[1.0, 5.0], [3.0, 5.0]])
    mean, std = normalization_stats(obs)
    np.testing.assert_allclose(mean, [2.0, 5.0])
    np.testing.assert_allclose(std, [1.0, 1.0])  # dim 0: std 1; dim 1 constant -> 1


def test_chunk_length_divides_epochs_and_checkpoints():
    assert chunk_epochs(TrainConfig(epochs=1000, checkpoint_every=200, progress_every=10)) == 10
    assert chunk_epochs(TrainConfig(epochs=7, checkpoint_every=200, progress_every=10)) == 1
    assert chunk_epochs(TrainConfig(epochs=90, checkpoint_every=20, progress_every=25)) == 10


def test_config_defaults_profiles_and_validation():
    paper = TrainConfig.from_profile("paper")
    assert (paper.ensemble_size, paper.hidden, paper.lr, paper.batch_size, paper.epochs) == (
        5,
        (1024, 1024),
        1e-3,
        512,
        1000,
    )
    assert TrainConfig(model="mdn").lr == 1e-4 and TrainConfig(model="mdn").ensemble_size == 1
    assert TrainConfig(model="lstm").hidden == (512, 512)
    cpu = TrainConfig.from_profile("cpu", epochs=7, lr=None)
    assert cpu.hidden == (256, 256) and cpu.epochs == 7 and cpu.lr == 1e-3
    assert TrainConfig.from_dict(cpu.to_dict()) == cpu
    with pytest.raises(ElicitError, match="dropout"):
        TrainConfig(dropout=1.5)
    with pytest.raises(ElicitError, match="unknown profile"):
        TrainConfig.from_profile("gpu")
    with pytest.raises(ElicitError, match="unknown model"):
        TrainConfig(model="transformer")


def test_param_names_round_trip():
    params = {"Trunk_0": {"Dense_0": {"kernel": np.ones((2, 3))}}, "head": {"b": np.zeros(1)}}
    flat = flatten_params(params)
    assert sorted(flat) == ["Trunk_0/Dense_0/kernel", "head/b"]
    assert unflatten_params(flat)["Trunk_0"]["Dense_0"]["kernel"].shape == (2, 3)
