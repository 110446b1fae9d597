"""Scoring and MJX rollouts split their batch across two forced host devices and give the
same numbers as on one device (a subprocess: the device count is fixed when JAX starts)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import jax, numpy as np
    import elicit_jax.compat.score as score
    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.compat.thresholds import Thresholds
    from elicit_jax.data.demos import from_episodes
    from elicit_jax.policy.base import init_policy
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.rollout_mjx import rollout_mjx, rollout_mjx_on_devices

    assert jax.device_count() == 2, jax.devices()

    # --- scoring: 58 rows; chunk 7 becomes 8 on two devices (58 = 7 * 8 + 2) ----------------
    rng = np.random.default_rng(0)
    eps = [{"obs": rng.normal(size=(t, 5)).astype(np.float32),
            "action": rng.uniform(-1, 1, size=(t, 3)).astype(np.float32)}
           for t in (7, 23, 4, 13, 11)]
    demos = from_episodes(eps, operators=["a", "b", "a", "b", "a"], successes=[True] * 5)
    seen = []
    real = score.score_rows
    def spy(policy, obs, *args, **kw):
        seen.append(getattr(obs, "sharding", None))
        return real(policy, obs, *args, **kw)
    score.score_rows = spy
    for kind in ("mlp", "mdn"):
        policy = init_policy(jax.random.key(1), kind=kind, obs_dim=5, action_dim=3,
                             n_members=1 if kind == "mdn" else 3, hidden=(16, 16))
        eta = 0.5 if kind == "mlp" else 0.7  # about the median novelty of each
        cfg = ScoreConfig(thresholds=Thresholds(0.3, eta, "given"), chunk_size=7)
        one = score.score_demos(policy, demos, cfg, n_devices=1)
        seen.clear()
        compiles = real._cache_size()
        two = score.score_demos(policy, demos, cfg)
        assert real._cache_size() - compiles == 1, "one compile for all chunks"
        assert len(seen) == 8, len(seen)  # ceil(58 / 8)
        assert all(len(s.device_set) == 2 for s in seen), seen
        for k in ("likelihood", "novelty", "compatibility", "prediction"):
            np.testing.assert_allclose(two[k], one[k], rtol=1e-6, atol=1e-6, err_msg=k)
        np.testing.assert_array_equal(two["episode"], demos.episode)
        assert 0 < one["incompatible"].sum() < 58  # thresholds cut inside the data
    lstm = init_policy(jax.random.key(2), kind="lstm", obs_dim=5, action_dim=3, n_members=3,
                       hidden=(16,))
    # chunk 40: 40 // 16 = 2 length-16 episodes per call; 40 // 32 = 1 length-32 episode,
    # rounded up to 2 (one per device)
    cfg = ScoreConfig.from_preset("square-nut", chunk_size=40)
    one, two = score.score_demos(lstm, demos, cfg, 1), score.score_demos(lstm, demos, cfg)
    for k in ("likelihood", "novelty", "compatibility"):
        np.testing.assert_allclose(two[k], one[k], rtol=1e-6, atol=1e-6, err_msg=k)

    # --- MJX rollouts: 5 environments (padded to 6) on two devices ---------------------------
    task = make_task("reach-pillar")
    policy = init_policy(jax.random.key(3), kind="mlp", obs_dim=23, action_dim=7, n_members=2,
                         hidden=(32, 32))
    seeds = np.arange(20, 25)
    one = rollout_mjx(task, policy, seeds, horizon=3, n_devices=1)
    raw = rollout_mjx_on_devices(task, policy, seeds, horizon=3)
    shards = sorted((s.device.id, s.data.shape) for s in raw["final_obs"].addressable_shards)
    assert shards == [(0, (3, 23)), (1, (3, 23))], shards
    two = rollout_mjx(task, policy, seeds, horizon=3)
    assert two["final_obs"].shape == (5, 23)
    for k, v in one.items():
        np.testing.assert_allclose(two[k], v, rtol=1e-5, atol=1e-5, err_msg=k)
    start = task.init_states(seeds)[0]
    assert np.abs(one["final_obs"][:, :3] - start[:, :3]).max() > 1e-3  # the policy moved
    np.testing.assert_array_equal(np.asarray(raw["final_obs"])[5], two["final_obs"][4])
    print("OK")
    """
)


def test_scoring_and_mjx_rollouts_shard_across_two_forced_host_devices():
    env = dict(os.environ)
    # LLVM at -O0 halves the two MJX compiles; both device counts use the same flags.
    flags = " --xla_force_host_platform_device_count=2 --xla_backend_optimization_level=0"
    env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + flags).strip()
    env["JAX_PLATFORMS"] = "cpu"
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.strip().endswith("OK")
