"""Filtering: M-filter and baselines at pair/episode level; outputs are valid Demos."""

import jax
import numpy as np
import pyarrow.parquet as pq
import pytest

from elicit_jax.compat.filtering import (
    ExportSpec,
    FilterConfig,
    apply_drop,
    drop_mask,
    filter_demos,
    log_path,
)
from elicit_jax.compat.measures import ScoreConfig
from elicit_jax.compat.score_file import read_scores, score_file
from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.data.demos import from_episodes, read_demos, write_demos
from elicit_jax.errors import ElicitError
from elicit_jax.policy.base import init_policy


def _demos(seed, lengths, op):
    rng = np.random.default_rng(seed)
    eps = [
        {
            "obs": rng.normal(size=(t, 4)).astype(np.float32),
            "action": rng.uniform(-1, 1, size=(t, 2)).astype(np.float32),
        }
        for t in lengths
    ]
    return from_episodes(eps, operators=op, episode_ids=[10 + i for i in range(len(lengths))])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("filter")
    policy = init_policy(
        jax.random.key(0), kind="mlp", obs_dim=4, action_dim=2, n_members=3, hidden=(8,)
    )
    new, base = d / "new.parquet", d / "base.parquet"
    write_demos(new, _demos(1, (12, 30, 9, 20, 25), "op"))
    write_demos(base, _demos(2, (15, 15), "base"))
    # huge eta (all familiar) and lambda at the median of the per-episode largest errors:
    # about half the episodes have an incompatible pair (all of them are >= 9 steps, so one
    # pair exceeds 5% and rejects the episode)
    probe = d / "probe.parquet"
    score_file(policy, new, probe, ScoreConfig.from_preset("square-nut", chunk_size=32))
    p = read_scores(probe)[1]
    lam = float(np.median([p["likelihood"][p["episode"] == e].max() for e in range(10, 15)]))
    scores = d / "scores.parquet"
    score_file(
        policy, new, scores, ScoreConfig(thresholds=Thresholds(lam, 100.0, "given"), chunk_size=32)
    )
    return {"new": new, "base": base, "scores": scores, "dir": d}


def _scores():
    # 3 episodes: ids 0 (len 4), 1 (len 2), 2 (len 3)
    return {
        "episode": np.array([0, 0, 0, 0, 1, 1, 2, 2, 2]),
        "likelihood": np.array([0.1, 0.9, 0.2, 0.8, 0.05, 0.06, 0.5, 0.01, 0.02]),
        "novelty": np.array([0.01, 0.01, 0.3, 0.01, 0.2, 0.01, 0.01, 0.4, 0.01]),
        "incompatible": np.array([0, 1, 0, 1, 0, 0, 1, 0, 0], bool),
    }


def test_drop_masks_by_hand():
    s = _scores()
    drop, _ = drop_mask(s, FilterConfig())
    assert drop.tolist() == s["incompatible"].tolist()  # M-filter: the 3 incompatible pairs
    # budget 3 pairs: likelihood-only drops the 3 largest l: 0.9, 0.8, 0.5 (rows 1, 3, 6)
    drop, _ = drop_mask(s, FilterConfig(method="likelihood"))
    assert np.flatnonzero(drop).tolist() == [1, 3, 6]
    # novelty-only: the 3 largest nu: 0.4, 0.3, 0.2 (rows 7, 2, 4)
    drop, _ = drop_mask(s, FilterConfig(method="novelty"))
    assert np.flatnonzero(drop).tolist() == [2, 4, 7]
    # shortest episodes until >= 3 pairs: ep 1 (2 pairs) then ep 2 (3) -> 5 pairs
    drop, _ = drop_mask(s, FilterConfig(method="shortest"))
    assert np.flatnonzero(drop).tolist() == [4, 5, 6, 7, 8]
    # episode level: ep 0 has 2/4 incompatible (> 5%), ep 2 has 1/3 -> both rejected
    drop, _ = drop_mask(s, FilterConfig(level="episode"))
    assert np.flatnonzero(drop).tolist() == [0, 1, 2, 3, 6, 7, 8]
    # longest 2 episodes: ep 0 (4) and ep 2 (3)
    drop2, _ = drop_mask(s, FilterConfig(level="episode", method="longest"))
    assert drop2.tolist() == drop.tolist()
    # random: same budget, seeded
    a, _ = drop_mask(s, FilterConfig(method="random", seed=1))
    b, _ = drop_mask(s, FilterConfig(method="random", seed=1))
    assert a.sum() == 3 and a.tolist() == b.tolist()
    # explicit thresholds recompute incompatibility: l >= 0.15 and nu < 0.05 -> rows 1, 3, 6
    drop, _ = drop_mask(s, FilterConfig(thresholds=Thresholds(0.15, 0.05, "given")))
    assert np.flatnonzero(drop).tolist() == [1, 3, 6]


def test_apply_drop_renumber_and_split():
    d = _demos(0, (5, 3), "op")
    drop = np.array([0, 0, 1, 0, 0, 0, 0, 1], bool)
    r = apply_drop(d, drop, "renumber")
    # episode 10 keeps source steps 0,1,3,4 renumbered 0..3; episode 11 keeps 0,1
    assert r.episode.tolist() == [10, 10, 10, 10, 11, 11]
    assert r.step.tolist() == [0, 1, 2, 3, 0, 1]
    assert r.extra["pre_filter_step"].tolist() == [0, 1, 3, 4, 0, 1]
    s = apply_drop(d, drop, "split")
    # episode 10 splits at the gap into [0, 1] and [3, 4]
    assert s.episode.tolist() == [0, 0, 1, 1, 2, 2]
    assert s.step.tolist() == [0, 1, 0, 1, 0, 1]
    assert s.extra["pre_filter_episode"].tolist() == [10, 10, 10, 10, 11, 11]
    with pytest.raises(ElicitError, match="drops every pair"):
        apply_drop(d, np.ones(8, bool))


@pytest.mark.parametrize(
    "level,method,mode",
    [
        ("pair", "m", "renumber"),
        ("pair", "m", "split"),
        ("episode", "m", "renumber"),
        ("pair", "random", "renumber"),
        ("episode", "longest", "renumber"),
    ],
)
def test_filter_round_trips_as_valid_demos(files, tmp_path, level, method, mode):
    out = tmp_path / "f.parquet"
    cfg = FilterConfig(level=level, method=method, pair_mode=mode)
    r = filter_demos(files["scores"], files["new"], out, cfg, base_path=files["base"])
    got = read_demos(out)  # validates contiguity, steps, dims
    base = read_demos(files["base"])
    new = read_demos(files["new"])
    # D_base kept whole and first
    np.testing.assert_array_equal(got.obs[: base.n_steps], base.obs)
    assert set(got.extra["subset"][: base.n_steps]) == {"base"}
    assert got.n_steps == base.n_steps + new.n_steps - r.pairs_dropped
    assert 0 < r.pairs_dropped < new.n_steps
    # the drop log lists exactly the dropped pairs, with a reason
    log = pq.read_table(log_path(out))
    assert log.num_rows == r.pairs_dropped
    assert all(log.column("reason").to_pylist())
    # kept new rows are exactly the non-dropped ones of D_new
    kept = (
        got.extra["pre_filter_episode"][base.n_steps :],
        got.extra["pre_filter_step"][base.n_steps :],
    )
    dropped = set(
        zip(log.column("episode").to_pylist(), log.column("step").to_pylist(), strict=True)
    )
    all_pairs = set(zip(new.episode.tolist(), new.step.tolist(), strict=True))
    assert set(zip(kept[0].tolist(), kept[1].tolist(), strict=True)) == all_pairs - dropped


def test_dropping_everything(files, tmp_path):
    cfg = FilterConfig(
        thresholds=Thresholds(1e-9, 1e9, "given"), level="episode"
    )  # every pair incompatible
    r = filter_demos(
        files["scores"], files["new"], tmp_path / "f.parquet", cfg, base_path=files["base"]
    )
    assert read_demos(tmp_path / "f.parquet").n_steps == read_demos(files["base"]).n_steps
    assert r.episodes_out == 0
    with pytest.raises(ElicitError, match="nothing left"):
        filter_demos(files["scores"], files["new"], tmp_path / "g.parquet", cfg)
    assert not (tmp_path / "g.parquet").exists()


def test_filter_refuses_scores_of_other_demos(files, tmp_path):
    with pytest.raises(ElicitError, match="different demonstrations file"):
        filter_demos(files["scores"], files["base"], tmp_path / "f.parquet", FilterConfig())


def test_bad_filter_config():
    with pytest.raises(ElicitError, match="unknown method"):
        FilterConfig(method="best")
    with pytest.raises(ElicitError, match="both lambda and eta"):
        FilterConfig.from_dict({"lambda_": 0.3, "eta": None})
    with pytest.raises(ElicitError, match="Thresholds value"):
        FilterConfig(thresholds=(0.3, 0.05))


def test_episode_filter_exports_a_robomimic_mask(tmp_path):
    import h5py

    from elicit_jax.data.robomimic import import_robomimic
    from elicit_jax.data.synthetic import ToyConfig, make_toy_robomimic

    src = tmp_path / "toy.hdf5"
    make_toy_robomimic(src, ToyConfig(demos_per_operator=3, horizon=40))
    demos_path = tmp_path / "toy.parquet"
    write_demos(
        demos_path,
        import_robomimic(
            src, obs_keys=("agent_pos", "goal_pos"), operators_from_masks="*_operator_*"
        ),
    )
    policy = init_policy(
        jax.random.key(0), kind="mlp", obs_dim=4, action_dim=2, n_members=3, hidden=(8,)
    )
    scores = tmp_path / "scores.parquet"
    score_file(policy, demos_path, scores, ScoreConfig.from_preset("square-nut", chunk_size=64))
    s = read_scores(scores)[1]
    # lambda between the per-episode largest errors: the lower half of episodes is accepted
    worst = np.array([s["likelihood"][s["episode"] == e].max() for e in range(6)])
    lam = float(np.sort(worst)[2] + 1e-6)
    kept_ids = np.flatnonzero(worst < lam)
    out = tmp_path / "compatible.hdf5"
    cfg = FilterConfig(thresholds=Thresholds(lam, 1e9, "given"), level="episode")
    r = filter_demos(
        scores,
        demos_path,
        tmp_path / "kept.parquet",
        cfg,
        export=ExportSpec("robomimic", str(out), mask_key="compatible"),
    )
    with h5py.File(out, "r") as f:
        names = sorted(x.decode() for x in f["mask/compatible"][:])
    # import numbered the episodes 0..5 in demo_N order, so episode i is demo_i
    assert names == sorted(f"demo_{i}" for i in kept_ids)
    assert r.export["episodes"] == len(kept_ids) == 3
    with pytest.raises(ElicitError, match="needs --level episode"):
        filter_demos(
            scores,
            demos_path,
            tmp_path / "k2.parquet",
            FilterConfig(),
            export=ExportSpec("robomimic", str(out), mask_key="x"),
        )
