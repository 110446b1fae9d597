"""Cutting per-demonstration scores: the method's own rule and the M-filter's budget, exactly;
curated outputs are valid demos with a drop log."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest

from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.curation.episodes import (
    EpisodeScores,
    MatchedRule,
    OwnRule,
    read_episode_scores,
    select_drop,
    write_episode_scores,
)
from elicit_jax.curation.select import curate_demos, matched_rule
from elicit_jax.data.demos import from_episodes, read_demos, write_demos
from elicit_jax.errors import ElicitError


def _scores(threshold=None, trusted=True):
    # positions:      0     1     2     3     4
    return EpisodeScores(
        "deminf",
        episode=np.array([10, 11, 12, 13, 14]),
        operator=np.array(["op"] * 5, object),
        length=np.array([4, 10, 3, 6, 5]),
        score=np.array([0.5, -0.2, 0.1, -0.2, 0.9]),
        threshold=threshold,
        trusted=trusted,
    )


def test_matched_pair_budget_drops_lowest_until_reached():
    # lowest first, ties by position: 1 (-0.2, 10 pairs), 3 (-0.2, 6), 2 (0.1, 3), 0, 4
    drop, why = select_drop(_scores(), MatchedRule(pairs=11))
    assert np.flatnonzero(drop).tolist() == [1, 3]  # 10 < 11 <= 16
    assert "16 pairs; matched to the M-filter's 11 pairs" in why
    drop, _ = select_drop(_scores(), MatchedRule(pairs=10))
    assert np.flatnonzero(drop).tolist() == [1]  # exactly reached
    drop, _ = select_drop(_scores(), MatchedRule(pairs=0))
    assert not drop.any()
    drop, _ = select_drop(_scores(), MatchedRule(pairs=1000))
    assert drop.all()


def test_matched_episode_budget_and_own_rules():
    drop, _ = select_drop(_scores(), MatchedRule(episodes=3))
    assert np.flatnonzero(drop).tolist() == [1, 2, 3]
    drop, _ = select_drop(_scores(), OwnRule(drop_fraction=0.4))  # round(0.4 * 5) = 2
    assert np.flatnonzero(drop).tolist() == [1, 3]
    drop, why = select_drop(_scores(threshold=0.1), OwnRule())  # score <= 0.1
    assert np.flatnonzero(drop).tolist() == [1, 2, 3] and "threshold" in why
    drop, why = select_drop(_scores(trusted=False), MatchedRule(pairs=10))
    assert not drop.any() and "no signal" in why


def test_rules_validate():
    with pytest.raises(ElicitError):
        MatchedRule()
    with pytest.raises(ElicitError):
        OwnRule(drop_fraction=1.0)
    with pytest.raises(ElicitError, match="non-finite"):
        EpisodeScores("x", np.array([0]), np.array(["a"]), np.array([1]), np.array([np.nan]))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("curate")
    rng = np.random.default_rng(0)

    def eps(lengths):
        return [
            {
                "obs": rng.normal(size=(t, 3)).astype(np.float32),
                "action": rng.uniform(-1, 1, (t, 2)).astype(np.float32),
            }
            for t in lengths
        ]

    write_demos(
        d / "new.parquet",
        from_episodes(eps((4, 10, 3, 6, 5)), operators="op", episode_ids=[10, 11, 12, 13, 14]),
    )
    write_demos(d / "base.parquet", from_episodes(eps((7, 7)), operators="base"))
    return d


def test_curated_file_keeps_the_rest_renumbered_with_base_first_and_logs_drops(files):
    scores = _scores()
    out = files / "kept.parquet"
    r = curate_demos(
        scores, files / "new.parquet", out, MatchedRule(pairs=11), files / "base.parquet"
    )
    assert (r.pairs_in, r.pairs_dropped, r.episodes_in, r.episodes_out) == (28, 16, 5, 3)
    kept = read_demos(out)
    assert kept.extra["subset"].tolist().count("base") == 14
    new_rows = kept.extra["subset"] == "new"
    assert sorted(set(kept.extra["pre_filter_episode"][new_rows].tolist())) == [10, 12, 14]
    log = pq.read_table(r.log_path).to_pandas()
    assert sorted(set(log["episode"])) == [11, 13] and len(log) == 16
    assert set(log["score"]) == {-0.2}


def test_everything_dropped_without_base_writes_nothing_only_when_allowed(files):
    out = files / "none.parquet"
    with pytest.raises(ElicitError, match="every demonstration dropped"):
        curate_demos(_scores(), files / "new.parquet", out, MatchedRule(episodes=5))
    r = curate_demos(
        _scores(), files / "new.parquet", out, MatchedRule(episodes=5), allow_empty=True
    )
    assert r.out_path is None and r.episodes_out == 0 and not out.exists()


def test_scores_of_another_file_are_refused(files):
    other = EpisodeScores(
        "deminf",
        np.array([1, 2]),
        np.array(["a", "a"], object),
        np.array([3, 3]),
        np.array([0.0, 1.0]),
    )
    with pytest.raises(ElicitError, match="another file"):
        curate_demos(other, files / "new.parquet", files / "x.parquet", OwnRule())


def test_episode_scores_round_trip(files):
    s = _scores(threshold=0.25)
    path = files / "scores.parquet"
    write_episode_scores(
        path, s, config={"method": "deminf"}, inputs={"demos": files / "new.parquet"}
    )
    back = read_episode_scores(path)
    assert back.threshold == 0.25 and back.trusted
    np.testing.assert_array_equal(back.score, s.score)
    np.testing.assert_array_equal(back.episode, s.episode)


def test_matched_rule_from_a_scores_file(tmp_path):
    import pyarrow as pa

    from elicit_jax.artifact import make_header, write_parquet

    table = pa.table(
        {
            "episode": pa.array([0, 0, 0, 1, 1, 2, 2, 2, 2, 2]),
            "likelihood": pa.array([0.9, 0.1, 0.8, 0.1, 0.1, 0.7, 0.1, 0.1, 0.1, 0.1]),
            "novelty": pa.array([0.01, 0.01, 0.5, 0.01, 0.01, 0.01, 0.01, 0.01, 0.01, 0.01]),
        }
    )
    path = tmp_path / "scores.parquet"
    write_parquet(path, table, make_header("scores", 1))
    # λ 0.5, η 0.1: incompatible pairs are rows 0 and 5 (row 2 is novel)
    assert matched_rule(path, "pair", Thresholds(0.5, 0.1, "given")) == MatchedRule(pairs=2)
    # the 5% rule rejects episodes 0 and 2
    assert matched_rule(path, "episode", Thresholds(0.5, 0.1, "given")) == MatchedRule(episodes=2)


def test_cli_deminf_own_cut_and_matched_to_the_m_filter(files):
    import jax
    from typer.testing import CliRunner

    from elicit_jax.cli import app
    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.compat.score_file import read_scores, score_file
    from elicit_jax.policy.base import init_policy

    runner = CliRunner()
    own = files / "deminf-own.parquet"
    args = ["filter", "--method", "deminf", "--demos", str(files / "new.parquet")]
    res = runner.invoke(app, [*args, "--base", str(files / "base.parquet"), "-o", str(own)])
    assert res.exit_code == 0, res.output
    per_demo = read_episode_scores(files / "deminf-own.episode-scores.parquet")
    assert per_demo.report["n_base_pairs"] == 14 and per_demo.threshold is None
    kept = read_demos(own)
    lowest = int(per_demo.episode[np.argmin(per_demo.score)])  # round(0.2 * 5) = 1 demo
    new_eps = set(kept.extra["pre_filter_episode"][kept.extra["subset"] == "new"].tolist())
    assert new_eps == {10, 11, 12, 13, 14} - {lowest}
    assert "lowest 1 of 5 demos" in res.output

    policy = init_policy(jax.random.key(0), kind="mlp", obs_dim=3, action_dim=2, n_members=3,
                         hidden=(8,))  # fmt: skip
    scores = files / "m-scores.parquet"
    score_file(
        policy, files / "new.parquet", scores, ScoreConfig.from_preset("square-nut", chunk_size=32)
    )
    ell = read_scores(scores)[1]["likelihood"]
    lam = float(np.quantile(ell, 0.8))  # with η huge: the top 20% of pairs are M = 0
    n_inc = int((ell > lam).sum())  # the incompatible test is strict: ℓ > λ
    matched = files / "deminf-m.parquet"
    res = runner.invoke(app, [*args, "-o", str(matched), "--rate", "m", "--scores", str(scores),
                              "--lambda", str(lam), "--eta", "1e6"])  # fmt: skip
    assert res.exit_code == 0, res.output
    order = np.argsort(read_episode_scores(files / "deminf-m.episode-scores.parquet").score,
                       kind="stable")  # fmt: skip
    cum = np.cumsum(np.array([4, 10, 3, 6, 5])[order])
    n_drop = int(np.searchsorted(cum, n_inc) + 1)
    assert read_demos(matched).n_steps == 28 - int(cum[n_drop - 1])
    assert f"matched to the M-filter's {n_inc} pairs" in res.output

    res = runner.invoke(app, [*args, "-o", str(files / "y.parquet"), "--rate", "m"])
    assert res.exit_code == 1 and "give --scores" in str(res.exception)
    res = runner.invoke(app, ["filter", "--demos", str(files / "new.parquet"), "-o",
                              str(files / "z.parquet")])  # fmt: skip
    assert res.exit_code == 1 and "give --scores" in str(res.exception)
