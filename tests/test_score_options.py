"""Scoring options beyond the paper's defaults: clipping bounds from the demos, action scaling,
MC-dropout; thresholds that follow the demos' task."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from fixtures_data import tiny_episodes, tiny_train_config
from typer.testing import CliRunner

from elicit_jax.cli import app
from elicit_jax.compat.measures import ScoreConfig
from elicit_jax.compat.score import score_demos
from elicit_jax.compat.score_file import read_scores
from elicit_jax.data.demos import from_episodes, write_demos
from elicit_jax.errors import ElicitError
from elicit_jax.policy.base import init_policy


def _zero_policy(action_dim, dropout=0.0, **kw):
    """A policy whose every member predicts exactly 0 (all parameters zero)."""
    p = init_policy(
        jax.random.key(0),
        kind="mlp",
        obs_dim=2,
        action_dim=action_dim,
        n_members=2,
        hidden=(4,),
        dropout=dropout,
    )
    return p.replace(params=jax.tree.map(jnp.zeros_like, p.params), **kw)


def _demos(actions, low=-1.0, high=1.0):
    actions = np.asarray(actions, np.float32)
    ep = {"obs": np.zeros((len(actions), 2), np.float32), "action": actions}
    return from_episodes([ep], operators="op", action_low=low, action_high=high)


def test_member_average_clips_to_the_demos_recorded_bounds():
    demos = _demos([[1.5, 0.3]], low=(-2.0, -2.0), high=(2.0, 2.0))
    cfg = ScoreConfig.from_preset("square-nut", likelihood="member-average")
    got = score_demos(_zero_policy(2), demos, cfg)["likelihood"][0]
    assert got == pytest.approx((1.5**2 + 0.3**2) / 2)  # 1.17; a fixed ±1 clip gave 0.545
    fixed = score_demos(
        _zero_policy(2),
        demos,
        ScoreConfig.from_preset("square-nut", likelihood="member-average", clip=1),
    )
    assert fixed["likelihood"][0] == pytest.approx((1.0 + 0.09) / 2)


def test_action_scaling_uses_the_training_action_std():
    demos = _demos([[1.0, 0.0, 1.0]])
    policy = _zero_policy(3, action_std=jnp.array([0.5, 0.0, 2.0]))
    std = score_demos(policy, demos, ScoreConfig.from_preset("square-nut", action_scale="std"))[
        "likelihood"
    ][0]
    # dim 1 never moved in training: scored in units of the others' median std (1.25)
    assert std == pytest.approx((2.0**2 + 0.0 + 0.5**2) / 3)
    none = score_demos(policy, demos, ScoreConfig.from_preset("square-nut"))["likelihood"][0]
    assert none == pytest.approx(2.0 / 3)
    with pytest.raises(ElicitError, match="predates"):
        score_demos(
            _zero_policy(3), demos, ScoreConfig.from_preset("square-nut", action_scale="std")
        )


def test_an_operator_driving_a_dim_the_base_never_moved_is_told_apart_under_std_scaling():
    """Issue #45 item 8: with the still dim left out, an operator driving it at ±0.9 got
    exactly the unmodified operator's ℓ."""
    policy = _zero_policy(3, action_std=jnp.array([0.5, 0.0, 2.0]))
    cfg = ScoreConfig.from_preset("square-nut", action_scale="std")
    plain = score_demos(policy, _demos([[0.5, 0.0, 1.0]]), cfg)["likelihood"][0]
    driving = score_demos(policy, _demos([[0.5, 0.9, 1.0]]), cfg)["likelihood"][0]
    assert driving > plain + 0.1
    assert driving - plain == pytest.approx((0.9 / 1.25) ** 2 / 3)


def test_std_scores_file_records_the_still_dims(tmp_path):
    from elicit_jax.compat.score_file import score_file

    policy = _zero_policy(3, action_std=jnp.array([0.5, 0.0, 2.0]))
    write_demos(tmp_path / "d.parquet", _demos([[0.5, 0.9, 1.0]]))
    cfg = ScoreConfig.from_preset("square-nut", action_scale="std")
    score_file(policy, tmp_path / "d.parquet", tmp_path / "s.parquet", cfg)
    header, _ = read_scores(tmp_path / "s.parquet")
    assert header["still_action_dims"] == [1]
    assert "never moved" in header["action_scale_note"]


def test_mc_dropout_scoring_is_seeded_and_chunk_independent():
    rng = np.random.default_rng(0)
    policy = init_policy(
        jax.random.key(1), kind="mlp", obs_dim=2, action_dim=2, n_members=3, hidden=(16, 16),
        dropout=0.5,
    )  # fmt: skip
    eps = [{"obs": rng.normal(size=(37, 2)), "action": rng.uniform(-1, 1, size=(37, 2))}]
    demos = from_episodes(eps, operators="op")
    cfg = ScoreConfig.from_preset("square-nut", dropout_samples=4, dropout_seed=7, chunk_size=16)
    a = score_demos(policy, demos, cfg)
    b = score_demos(
        policy,
        demos,
        ScoreConfig.from_preset("square-nut", dropout_samples=4, dropout_seed=7, chunk_size=64),
    )
    # masks are keyed by row, not chunk (what differs is float rounding of other batch shapes)
    np.testing.assert_allclose(a["novelty"], b["novelty"], rtol=1e-5)
    again = score_demos(policy, demos, cfg)
    np.testing.assert_array_equal(a["novelty"], again["novelty"])  # deterministic given the seed
    c = score_demos(
        policy,
        demos,
        ScoreConfig.from_preset("square-nut", dropout_samples=4, dropout_seed=8, chunk_size=16),
    )
    assert np.abs(a["novelty"] - c["novelty"]).max() > 1e-4
    det = score_demos(policy, demos, ScoreConfig.from_preset("square-nut", chunk_size=16))
    # dropout on makes members disagree more: novelty is inflated, as in the original code
    assert a["novelty"].mean() > det["novelty"].mean()
    # pinned semantics: member k, pass i of row r uses fold_in(fold_in(fold_in(key(seed), r), k), i)
    x = policy.normalize(jnp.asarray(demos.obs[5:6]))
    key = jax.random.fold_in(jax.random.fold_in(jax.random.fold_in(jax.random.key(7), 5), 2), 3)
    p2 = jax.tree.map(lambda v: v[2], policy.params)
    manual = policy.module.apply({"params": p2}, x, True, rngs={"dropout": key})[0]
    keys = jax.vmap(lambda r: jax.random.fold_in(jax.random.key(7), r))(jnp.arange(5, 6))
    samples = policy.sample_members(jnp.asarray(demos.obs[5:6]), keys, 4)
    np.testing.assert_allclose(samples[2 * 4 + 3, 0], manual, rtol=1e-6)
    with pytest.raises(ElicitError, match="trained with dropout"):
        score_demos(
            _zero_policy(2),
            _demos([[0.1, 0.2]]),
            ScoreConfig.from_preset("square-nut", dropout_samples=2),
        )


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from elicit_jax.policy.train import train_policy

    d = tmp_path_factory.mktemp("score-options")
    eps = tiny_episodes()
    for task in ("NutAssemblyRound", "my-task"):
        write_demos(d / f"{task}.parquet", from_episodes(eps, operators="op", task=task))
    cfg = tiny_train_config(val_fraction=0.0)
    train_policy(from_episodes(eps, operators="op"), cfg, d / "run", quiet=True)
    return d


def _score(run, demos, *extra):
    out = run / f"s-{demos}.parquet"
    r = CliRunner().invoke(
        app,
        [
            "score",
            "--policy",
            str(run / "run"),
            "--demos",
            str(run / demos),
            "-o",
            str(out),
            "--overwrite",  # each test scores into the same file again
            *extra,
        ],
    )
    return r, out


def test_thresholds_follow_the_task(run):
    r, out = _score(run, "NutAssemblyRound.parquet")
    assert r.exit_code == 0, r.output
    header, _ = read_scores(out)
    assert header["thresholds"] == {"lambda": 0.35, "eta": 0.05}  # round-nut, not square-nut
    assert header["thresholds_source"] == "preset round-nut (task NutAssemblyRound)"
    r, out = _score(run, "my-task.parquet")
    assert r.exit_code == 0 and "has no paper preset" in r.output
    assert "borrowed" in read_scores(out)[0]["thresholds_source"]
    r, _ = _score(run, "my-task.parquet", "--preset", "hammer")
    assert "unknown preset 'hammer'" in str(r.exception)
    help_text = CliRunner().invoke(app, ["score", "--help"]).output
    assert "hammer-drawer" in help_text


def test_checkpoint_records_action_std_and_std_scoring_runs(run):
    from elicit_jax.policy.loaded import load_policy

    policy = load_policy(run / "run").policy
    assert policy.action_std is not None and policy.action_std.shape == (2,)
    r, out = _score(run, "my-task.parquet", "--action-scale", "std", "--lambda", "1", "--eta", "1")
    assert r.exit_code == 0, r.output
    header, s = read_scores(out)
    assert header["config"]["action_scale"] == "std" and np.isfinite(s["likelihood"]).all()
