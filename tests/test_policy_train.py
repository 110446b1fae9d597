"""Training: every model type learns a tiny known mapping; seeds, determinism, round trips."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pyarrow.parquet as pq
import pytest

from elicit_jax.artifact import read_header
from elicit_jax.data.demos import fields_from_sizes, from_episodes
from elicit_jax.errors import ElicitError
from elicit_jax.policy.base import init_policy
from elicit_jax.policy.checkpoint import check_compatible, list_checkpoints
from elicit_jax.policy.config import TrainConfig
from elicit_jax.policy.dataset import prepare
from elicit_jax.policy.loaded import load_policy
from elicit_jax.policy.train import train_policy, train_states

OBS, ACT = 4, 2
# Trained models reach a val MSE of ~0.01 on this task; an untrained one sits near the
# variance of the targets (~0.45), so 0.05 separates "learned" from "random".
LEARNED_MSE = 0.05


def _demos(n_episodes: int = 12, length: int = 20, seed: int = 0, obs_dim: int = OBS):
    rng = np.random.default_rng(seed)
    w = np.random.default_rng(123).normal(size=(obs_dim, ACT))
    eps = []
    for _ in range(n_episodes):
        obs = rng.normal(size=(length, obs_dim)).astype(np.float32) * 2.0 + 1.0
        eps.append({"obs": obs, "action": np.tanh((obs - 1.0) / 2.0 @ w).astype(np.float32)})
    return from_episodes(
        eps, obs_fields=fields_from_sizes([("pos", 2), ("obj", obs_dim - 2)]), task="toy"
    )


def _config(model: str, **kw) -> TrainConfig:
    base = dict(
        model=model,
        hidden=(32, 32),
        epochs=60,
        checkpoint_every=30,
        progress_every=30,
        batch_size=32,
        dropout=0.0,
        lr=3e-3,
        ensemble_size=1 if model == "mdn" else 3,
        seq_len=5,
        seeds=(0,),
    )
    return TrainConfig(**{**base, **kw})


@pytest.fixture(scope="module")
def demos():
    return _demos()


@pytest.fixture(scope="module")
def runs(demos, tmp_path_factory):
    """One trained run per model type (MLP with two seeds)."""
    root = tmp_path_factory.mktemp("runs")
    configs = {
        "mlp": _config("mlp", seeds=(0, 1)),
        "mdn": _config("mdn"),
        "lstm": _config("lstm", epochs=30, checkpoint_every=15, progress_every=15),
    }
    return {m: (train_policy(demos, c, root / m, quiet=True), c) for m, c in configs.items()}


def _val_mse(policy, demos, run: Path, seed: int = 0) -> float:
    val_ids = read_header(run / f"seed{seed}")["val_episodes"]
    assert val_ids, "the split must hold out at least one episode"
    errs = []
    for ep in demos.select_episodes(val_ids).episodes():
        pred = jnp.mean(policy.members(jnp.asarray(ep["obs"])), axis=0)
        errs.append(np.mean((np.asarray(pred) - ep["action"]) ** 2))
    return float(np.mean(errs))


@pytest.mark.parametrize("model", ["mlp", "mdn", "lstm"])
def test_every_model_learns_the_mapping(runs, demos, model):
    run, config = runs[model]
    policy = load_policy(run / "seed0", "best").policy
    untrained = init_policy(
        jax.random.key(0),
        kind=model,
        obs_dim=OBS,
        action_dim=ACT,
        n_members=config.ensemble_size,
        hidden=config.hidden,
        reset_every=policy.reset_every,
        obs_mean=policy.obs_mean,
        obs_std=policy.obs_std,
    )
    assert _val_mse(policy, demos, run) < LEARNED_MSE
    assert _val_mse(untrained, demos, run) > 4 * LEARNED_MSE


def test_loss_curve_and_header(runs):
    run, config = runs["mlp"]
    table = pq.read_table(run / "seed0" / "loss.parquet").to_pandas()
    assert list(table["epoch"]) == list(range(1, config.epochs + 1))
    assert table["train_loss"].iloc[-1] < 0.2 * table["train_loss"].iloc[0]
    header = read_header(run / "seed0")
    best = header["best_epoch"]
    assert header["best_val_loss"] == pytest.approx(table["val_loss"].min())
    assert table["val_loss"].iloc[best - 1] == pytest.approx(table["val_loss"].min())
    assert header["model"]["obs_fields"] == ["pos", "obj"]
    # numerics depend on the XLA CPU thread count: the checkpoint records it
    assert header["runtime"]["PJRT_NPROC"] == os.environ["PJRT_NPROC"]
    assert "--xla_cpu_use_fusion_emitters=false" in header["runtime"]["XLA_FLAGS"]
    assert list_checkpoints(run) == {0: [30, 60, "best"], 1: [30, 60, "best"]}
    with np.load(run / "seed0" / "params" / "epoch_0060.npz") as f:
        assert f["Trunk_0/Dense_0/kernel"].shape == (3, OBS, 32)


def test_members_and_seeds_differ(runs, demos):
    run, _ = runs["mlp"]
    p0 = load_policy(run, "final", seed=0).policy
    p1 = load_policy(run, "final", seed=1).policy
    obs = jnp.asarray(demos.obs[:50])
    m0, m1 = np.asarray(p0.members(obs)), np.asarray(p1.members(obs))
    assert m0.shape == (3, 50, ACT)
    assert np.abs(m0 - m1).max() > 1e-3
    assert np.abs(m0[0] - m0[1]).max() > 1e-3
    with pytest.raises(ElicitError, match="seeds"):
        load_policy(run)


def test_training_is_bit_for_bit_deterministic(runs, demos, tmp_path):
    run, config = runs["mlp"]
    again = train_policy(demos, config, tmp_path / "again", quiet=True)
    for name in ("epoch_0030.npz", "epoch_0060.npz", "best.npz"):
        for seed in (0, 1):
            a = np.load(run / f"seed{seed}" / "params" / name)
            b = np.load(again / f"seed{seed}" / "params" / name)
            for key in a.files:
                np.testing.assert_array_equal(a[key], b[key])


def test_save_load_gives_identical_predictions(runs, demos):
    run, config = runs["mlp"]
    cfg = dataclasses.replace(config, seeds=(0, 1))
    data = prepare(demos, cfg.val_fraction, 1)
    states, _, _ = train_states(cfg, data, OBS, ACT, cfg.seeds)
    loaded = load_policy(run, "final", seed=1).policy
    in_memory = loaded.replace(params=jax.tree.map(lambda x: x[1], states.params))
    obs = jnp.asarray(demos.obs)
    np.testing.assert_array_equal(loaded.members(obs), in_memory.members(obs))


def test_mismatched_data_and_missing_checkpoints_fail_clearly(runs, tmp_path):
    run, _ = runs["mlp"]
    policy = load_policy(run / "seed0").policy
    other = _demos(n_episodes=2, obs_dim=OBS + 1)
    with pytest.raises(ElicitError, match=r"obs_dim=5.*obs_dim=4"):
        check_compatible(policy, other, "other.parquet")
    renamed = dataclasses.replace(_demos(2), obs_fields=fields_from_sizes([("a", 2), ("b", 2)]))
    with pytest.raises(ElicitError, match="obs fields"):
        check_compatible(policy, renamed)
    with pytest.raises(ElicitError, match="no checkpoint for epoch 45"):
        load_policy(run / "seed0", 45)
    with pytest.raises(ElicitError, match="not found"):
        load_policy(tmp_path / "nothing")


def test_lstm_act_with_carried_state_matches_members(runs, demos):
    policy = load_policy(runs["lstm"][0] / "seed0").policy
    assert policy.reset_every == 5
    obs = jnp.asarray(demos.obs[:12])  # 12 steps: the state is reset at steps 0, 5 and 10
    seq = np.asarray(jnp.mean(policy.members(obs), axis=0))
    carry = policy.init_carry(1)
    stepped = []
    for t in range(12):
        carry, a = policy.act(carry, obs[t : t + 1])
        stepped.append(np.asarray(a[0]))
    np.testing.assert_allclose(np.stack(stepped), seq, atol=1e-5)


def test_mdn_spread(runs, demos):
    policy = load_policy(runs["mdn"][0] / "seed0").policy
    obs = jnp.asarray(demos.obs[:10])
    spread = np.asarray(policy.spread(obs))
    assert spread.shape == (10, ACT) and np.all(spread >= 0)
    assert policy.members(obs).shape == (1, 10, ACT)
    assert load_policy(runs["mlp"][0] / "seed0").policy.spread(obs) is None


def test_bootstrap_gives_each_member_its_own_resample(demos):
    from elicit_jax.policy.loop import init_states
    from elicit_jax.policy.train import _loop_spec

    cfg = _config("mlp", bootstrap=True)
    data = prepare(demos, cfg.val_fraction, 1)
    samples = np.asarray(init_states(_loop_spec(cfg, data, OBS, ACT), (0,)).samples[0])
    assert samples.shape == (3, data.n_train)
    assert samples.min() >= 0 and samples.max() < data.n_train
    # With replacement: each member sees ~63% distinct samples, and the members differ.
    assert all(len(np.unique(s)) < 0.8 * data.n_train for s in samples)
    assert not np.array_equal(samples[0], samples[1])


def test_gradient_clipping_bounds_the_update(demos):
    from elicit_jax.policy.loop import init_states
    from elicit_jax.policy.train import _loop_spec

    # Adam's step is lr * m / (sqrt(v) + eps) ~ lr * sign(g) when |g| >> eps = 1e-8, so a clip
    # that is large changes nothing, while a clip at 1e-12 makes |g| << eps and every step
    # ~ lr * g / eps <= 3e-3 * 1e-12 / 1e-8 = 3e-7: after 2 epochs x 8 batches the weights must
    # have moved by less than 16 * 3e-7 ~ 5e-6, against ~1e-2 without clipping.
    data = prepare(demos, 0.2, 1)
    moved = {}
    for clip in (None, 1e3, 1e-12):
        cfg = _config("mlp", epochs=2, checkpoint_every=1, progress_every=1, grad_clip=clip)
        init = init_states(_loop_spec(cfg, data, OBS, ACT), cfg.seeds).params
        final = train_states(cfg, data, OBS, ACT, cfg.seeds)[0].params
        deltas = jax.tree.map(lambda a, b: float(jnp.max(jnp.abs(a - b))), init, final)
        moved[clip] = max(jax.tree.leaves(deltas))
    assert moved[None] > 1e-3
    assert moved[1e3] == pytest.approx(moved[None], rel=1e-6)
    assert moved[1e-12] < 5e-6


def test_cli_train_and_info(demos, tmp_path):
    from typer.testing import CliRunner

    from elicit_jax.cli import app
    from elicit_jax.data.demos import write_demos

    write_demos(tmp_path / "toy.parquet", demos)
    args = ["train", "--demos", str(tmp_path / "toy.parquet"), "--out", str(tmp_path / "run"),
            "--profile", "cpu", "--hidden", "32,32", "--epochs", "10", "--checkpoint-every", "5",
            "--batch-size", "32", "--ensemble-size", "2", "--seeds", "3", "--val-fraction", "0",
            "--quiet"]  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    header = read_header(tmp_path / "run" / "seed3")
    assert header["inputs"]["demos"]["path"] == str(tmp_path / "toy.parquet")
    assert header["config"]["hidden"] == [32, 32] and header["seed"] == 3
    # No validation split: the best checkpoint is chosen by training loss.
    assert header["best_selected_by"] == "train_loss" and header["final_val_loss"] is None
    assert header["val_episodes"] == [] and len(header["train_episodes"]) == 12
    assert list_checkpoints(tmp_path / "run") == {3: [5, 10, "best"]}
    result = CliRunner().invoke(app, ["info", str(tmp_path / "run")])
    assert result.exit_code == 0 and "training_run" in result.output
    bad = CliRunner().invoke(app, [*args[:-1], "--hidden", "3x2"])
    assert bad.exit_code != 0
