"""collect and evaluate end to end: artifacts, a tiny policy that learns reach-pillar, both
backends with the policy in the loop."""

import dataclasses

import numpy as np
import pandas as pd
import pytest
from fixtures_data import cli_ok
from typer.testing import CliRunner

from elicit_jax.artifact import read_header
from elicit_jax.cli import app
from elicit_jax.data.demos import read_demos
from elicit_jax.errors import ElicitError
from elicit_jax.sim.evaluate import EvalConfig, eval_seeds, summarize


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    from elicit_jax.policy.config import TrainConfig
    from elicit_jax.policy.train import train_policy

    d = tmp_path_factory.mktemp("sim")
    cli_ok("collect", "--task", "reach-pillar", "--operator", "base", "--episodes", "40",
           "--seed", "3", "-o", str(d / "base.parquet"))  # fmt: skip
    cfg = TrainConfig(
        hidden=(64, 64),
        ensemble_size=2,
        dropout=0.0,
        epochs=200,
        batch_size=128,
        checkpoint_every=100,
        progress_every=50,
        seeds=(0, 1),
    )
    train_policy(read_demos(d / "base.parquet"), cfg, d / "runs", quiet=True)
    return d


def test_collect_writes_valid_demos(work):
    demos = read_demos(work / "base.parquet")
    header = read_header(work / "base.parquet")
    assert demos.task == "reach-pillar" and demos.n_episodes == 40
    assert set(demos.operator) == {"base"} and demos.success.all()
    assert (demos.obs_dim, demos.action_dim) == (23, 7)
    assert {f.name: (f.start, f.stop) for f in demos.obs_fields} == {
        "robot0_eef_pos": (0, 3),
        "robot0_eef_quat": (3, 7),
        "robot0_gripper_qpos": (7, 9),
        "object": (9, 23),
    }
    assert header["config"]["operator"] == "base" and header["seed"] == 3
    assert header["provenance"]["attempt_success_rate"] == 1.0
    # episode e starts from initial-state seed 3 * 100000 + e (one success per attempt)
    first = demos.extra["init_seed"][[s for _, s, _ in demos.episode_bounds()]]
    np.testing.assert_array_equal(first, 300_000 + np.arange(40))
    # each episode ends at its first success, with the sparse reward there only
    for ep in demos.episodes():
        assert ep["reward"][-1] == 1.0 and ep["reward"][:-1].sum() == 0.0


def test_collect_is_deterministic(work, tmp_path):
    cli_ok("collect", "--task", "reach-pillar", "--operator", "base", "--episodes", "40",
           "--seed", "3", "-o", str(tmp_path / "again.parquet"))  # fmt: skip
    a, b = read_demos(work / "base.parquet"), read_demos(tmp_path / "again.parquet")
    np.testing.assert_array_equal(a.obs, b.obs)
    np.testing.assert_array_equal(a.action, b.action)


def test_collect_bad_input(tmp_path):
    result = CliRunner().invoke(
        app, ["collect", "--task", "square-nut", "--operator", "nobody", "-o", str(tmp_path / "x")]
    )
    assert result.exit_code != 0 and isinstance(result.exception, ElicitError)
    assert not (tmp_path / "x").exists()
    for flag in ("--max-attempts", "--threads"):
        args = ["collect", "--task", "reach-pillar", flag, "-1", "-o", str(tmp_path / "x")]
        result = CliRunner().invoke(app, args)
        assert str(result.exception) == f"{flag} must be >= 0 (0: the default), got -1"
    assert not (tmp_path / "x").exists()
    for field in ("horizon", "threads"):
        with pytest.raises(ElicitError, match=f"--{field} must be >= 0"):
            EvalConfig(**{field: -1})


def test_evaluate_tiny_policy_learns_reach_pillar(work):
    out = work / "evals.parquet"
    result = cli_ok("evaluate", "--policy", f"tiny={work / 'runs'}", "--task", "reach-pillar",
                    "--rollouts", "20", "--backend", "mujoco", "--checkpoint", "all",
                    "--select", "best", "-o", str(out))  # fmt: skip
    assert "tiny" in result.output
    assert "biased upwards" in " ".join(result.output.split())  # chosen on these rollouts
    table = pd.read_parquet(out)
    header = read_header(out)
    assert header["kind"] == "rollouts" and header["backend"] == "mujoco"
    # 2 seeds x 3 checkpoints (100, 200, best) x 20 rollouts, all from the same initial states
    assert len(table) == 2 * 3 * 20
    for _, g in table.groupby(["seed", "checkpoint"]):
        np.testing.assert_array_equal(g.init_seed, eval_seeds(EvalConfig(rollouts=20)))
    ok = table[table.success]
    assert (ok.steps_to_success == ok.length).all() and (ok.ret == 1.0).all()
    assert (table[~table.success].steps_to_success == -1).all()
    (row,) = header["summary"]
    assert row["n_seeds"] == 2 and row["success_mean"] >= 80.0  # the tiny policy learned
    cli_ok("info", str(out))


def test_summarize_by_hand():
    rows = pd.DataFrame(
        {
            "policy": ["p"] * 8,
            "seed": [0, 0, 0, 0, 1, 1, 1, 1],
            "checkpoint": ["a", "a", "b", "b", "a", "a", "b", "b"],
            "success": [1, 0, 1, 1, 0, 0, 1, 0],
            "length": [5, 10, 5, 6, 10, 10, 7, 10],
            "unstable": [0, 0, 0, 0, 0, 1, 0, 0],
        }
    ).astype({"success": bool, "unstable": bool})
    best = summarize(rows, "best").iloc[0]
    # seed 0: a 50%, b 100% -> b; seed 1: a 0%, b 50% -> b; mean 75; std over seeds with
    # ddof 1 (as the study tables): sqrt(((100-75)^2 + (50-75)^2) / (2-1)) = sqrt(1250)
    assert best.checkpoint == "s0:b,s1:b"
    assert best.success_mean == 75.0
    assert best.success_std == pytest.approx(1250**0.5)  # 35.36, not ddof 0's 25
    assert best.mean_length == pytest.approx((5.5 + 8.5) / 2)
    assert best.unstable == 0  # the diverged rollout was in seed 1's checkpoint a
    per = summarize(rows, "all").set_index("checkpoint")
    assert per.loc["a", "success_mean"] == 25.0 and per.loc["b", "success_mean"] == 75.0
    # checkpoint a: seeds 50% and 0% -> sqrt((25^2 + 25^2) / 1)
    assert per.loc["a", "success_std"] == pytest.approx(1250**0.5)
    one = summarize(rows[rows.seed == 0], "best").iloc[0]
    assert (one.n_seeds, one.success_std) == (1, 0.0)  # one seed: no spread, never NaN


def test_mjx_and_c_backends_agree_with_the_policy_in_the_loop(work):
    """Same policy, same initial states, 6 control steps: same final observations."""
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.evaluate import rollout_mujoco_policy
    from elicit_jax.sim.rollout_mjx import rollout_mjx

    task = make_task("reach-pillar")
    policy = load_policy(work / "runs", "best", seed=0).policy
    seeds = np.arange(7, 11)
    m = rollout_mjx(task, policy, seeds, horizon=6)
    c = rollout_mujoco_policy(task, policy, seeds, horizon=6)
    np.testing.assert_allclose(m["final_obs"], c["final_obs"], atol=5e-3)
    np.testing.assert_array_equal(m["success"], c["success"])
    assert not m["unstable"].any() and not c["unstable"].any()
    # pure and deterministic: the same call again gives the same numbers; other initial
    # states give other trajectories
    again = rollout_mjx(task, policy, seeds, horizon=6)
    np.testing.assert_array_equal(again["final_obs"], m["final_obs"])
    other = rollout_mjx(task, policy, seeds + 100, horizon=6)
    assert not np.allclose(other["final_obs"], m["final_obs"])
    start = task.init_states(seeds)[0]
    assert np.abs(m["final_obs"][:, 0] - start[:, 0]).min() > 0.01  # the policy moved


def test_mjx_and_c_success_rates_statistically_consistent(work):
    """Same policy, 24 seeded initial states, full horizon on both backends: the exact McNemar
    test on the paired outcomes does not reject equal success rates (p > 0.01); the same test
    rejects a randomly initialised policy's C outcomes against the trained policy's."""
    import jax

    from elicit_jax.policy.base import init_policy
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.sim.compare import compare_backends, mcnemar_exact
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.evaluate import rollout_mujoco_policy

    task = make_task("reach-pillar")
    policy = load_policy(work / "runs", "best", seed=0).policy
    seeds = eval_seeds(EvalConfig(rollouts=24, seed=1))
    test, m, c = compare_backends(task, policy, seeds)
    assert test.n == 24 and test.consistent(0.01), test
    assert test.rate_a >= 0.6 and test.rate_b >= 0.6, test  # a policy that mostly succeeds
    assert not m["unstable"].any() and not c["unstable"].any()
    broken = init_policy(jax.random.key(5), kind="mlp", obs_dim=23, action_dim=7,
                         n_members=2, hidden=(64, 64))  # fmt: skip
    b = rollout_mujoco_policy(task, broken, seeds, task.config.horizon)
    power = mcnemar_exact(m["success"], b["success"])
    assert power.rate_b <= 0.2 and not power.consistent(0.01), power


def test_evaluate_errors(work):
    with pytest.raises(ElicitError, match="unknown backend"):
        EvalConfig(backend="gpu")
    result = CliRunner().invoke(
        app,
        [
            "evaluate",
            "--policy",
            str(work / "runs"),
            "--task",
            "reach-pillar",
            "--checkpoint",
            "999",
        ],
    )
    assert result.exit_code != 0 and "no checkpoint '999'" in str(result.exception)


def test_rollouts_record_the_states_the_policy_acted_in(work):
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.evaluate import rollout_mujoco_policy
    from elicit_jax.sim.rollout_mujoco import BatchSim

    task = make_task("reach-pillar")
    policy = load_policy(work / "runs", 100, seed=0).policy
    seeds = eval_seeds(EvalConfig(rollouts=6))
    out = rollout_mujoco_policy(task, policy, seeds, 40, record_states=True)
    assert out["states"].shape == (6, 40, 23) and out["state_mask"].shape == (6, 40)
    with BatchSim(task, 6) as sim:
        np.testing.assert_allclose(out["states"][:, 0], sim.reset_seeds(seeds), atol=1e-6)
    # a rollout acts until its success (steps_to_success actions) or for the whole horizon
    acted = out["state_mask"].sum(axis=1)
    np.testing.assert_array_equal(acted, np.where(out["success"], out["steps_to_success"], 40))
    assert all(out["state_mask"][i, : acted[i]].all() for i in range(6))


def test_demo_score_on_real_rollouts_cross_validates_across_checkpoints(work):
    from elicit_jax.curation.demo_score import (
        DemoScoreConfig,
        collect_rollouts,
        score_demos,
        train_demo_score,
    )

    fast = {"steps": 200, "eval_every": 50}
    base = DemoScoreConfig(task="reach-pillar", rollouts=16, classifier=fast)
    full = collect_rollouts(work / "runs", base)
    assert full.epochs.tolist() == [100, 200]  # every saved epoch of the first seed
    lengths = np.bincount(full.rollout, minlength=len(full.success))
    # a horizon of the median success time makes about half of the rollouts fail
    horizon = int(np.median(lengths[full.success]))
    cfg = dataclasses.replace(base, horizon=horizon)
    rollouts = collect_rollouts(work / "runs", cfg)
    assert 0 < rollouts.success.mean() < 1
    model = train_demo_score(rollouts, cfg)
    assert model is not None
    assert model.report["validation_epoch"] == 200 and model.report["chosen_train_epoch"] == 100
    demos = read_demos(work / "base.parquet")
    scores = score_demos(demos, model, {})
    assert scores.trusted and len(scores.score) == 40
    assert ((scores.score >= 0) & (scores.score <= 1)).all()


def test_cli_filter_demo_score_end_to_end(work, tmp_path):
    out = tmp_path / "kept.parquet"
    res = cli_ok("filter", "--method", "demo-score", "--policy", str(work / "runs"), "--demos",
                 str(work / "base.parquet"), "--rollouts", "8", "-o", str(out))  # fmt: skip
    assert "checkpoint 100:" in res.output and "checkpoint 200:" in res.output
    assert (tmp_path / "kept.episode-scores.parquet").exists()
    kept = read_demos(out)
    assert 0 < kept.n_episodes <= 40
    header = read_header(out)
    assert header["config"]["curate"]["demo_score"]["task"] == "reach-pillar"  # from the demos
