"""Whole-dataset scoring: chunked/streamed equals direct computation, any chunk size."""

import dataclasses

import jax
import numpy as np
import pyarrow.parquet as pq
import pytest

from elicit_jax.artifact import content_sha256, read_header
from elicit_jax.compat.episode_summary import summarise_episodes
from elicit_jax.compat.measures import ScoreConfig
from elicit_jax.compat.score import score_demos
from elicit_jax.compat.score_file import read_scores, score_file
from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.data.demos import from_episodes, write_demos
from elicit_jax.errors import ElicitError
from elicit_jax.policy.base import init_policy

OBS, ACT = 5, 3


def _demos(seed=0, lengths=(7, 23, 4, 13, 11), obs_dim=OBS):
    rng = np.random.default_rng(seed)
    eps = [
        {
            "obs": rng.normal(size=(t, obs_dim)).astype(np.float32),
            "action": rng.uniform(-1, 1, size=(t, ACT)).astype(np.float32),
        }
        for t in lengths
    ]
    ops = ["base", "op1", "base", "op2", "op1"][: len(lengths)]
    return from_episodes(eps, operators=ops, successes=[True, False, True, True, False])


@pytest.fixture(scope="module")
def policies():
    key = jax.random.key(0)
    return {
        kind: init_policy(
            key,
            kind=kind,
            obs_dim=OBS,
            action_dim=ACT,
            n_members=1 if kind == "mdn" else 3,
            hidden=(16, 16),
        )
        for kind in ("mlp", "mdn", "lstm")
    }


@pytest.fixture(scope="module")
def demos_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("compat") / "new.parquet"
    write_demos(path, _demos())
    return path


def _reference(policy, demos, cfg):
    """Scores computed directly in numpy from the policy's members (no chunking/padding)."""
    if policy.kind == "lstm":
        preds = np.concatenate(
            [np.asarray(policy.members(ep["obs"])) for ep in demos.episodes()], axis=1
        )
    else:
        preds = np.asarray(policy.members(demos.obs))  # (K, N, A)
    a = demos.action
    mean = preds.mean(axis=0)
    if cfg.likelihood == "ensemble-mean":
        ell = ((mean - a) ** 2).mean(axis=1)
    else:
        ell = ((np.clip(preds, -1, 1) - np.clip(a, -1, 1)[None]) ** 2).mean(axis=2).mean(axis=0)
    spread = policy.spread(demos.obs)
    nu = (
        np.asarray(spread).mean(axis=1)
        if spread is not None
        else preds.std(axis=0, ddof=cfg.ddof).mean(axis=1)
    )
    lam, eta = cfg.thresholds.pair
    m = np.where(nu < eta, 1 - np.minimum(ell / lam, 1), 1.0)
    return ell, nu, m, mean


@pytest.mark.parametrize(
    "kind,likelihood,ddof",
    [
        ("mlp", "ensemble-mean", 0),
        ("mlp", "member-average", 1),
        ("mdn", "ensemble-mean", 0),
        ("lstm", "member-average", 1),
    ],
)
def test_scores_match_direct_computation(policies, kind, likelihood, ddof):
    demos = _demos()
    cfg = ScoreConfig(
        thresholds=Thresholds(0.3, 0.2, "given"), likelihood=likelihood, ddof=ddof, chunk_size=16
    )
    got = score_demos(policies[kind], demos, cfg)
    ell, nu, m, mean = _reference(policies[kind], demos, cfg)
    np.testing.assert_allclose(got["likelihood"], ell, rtol=2e-5, atol=1e-6)
    np.testing.assert_allclose(got["novelty"], nu, rtol=2e-5, atol=1e-6)
    np.testing.assert_allclose(got["compatibility"], m, rtol=2e-5, atol=1e-5)
    np.testing.assert_allclose(got["prediction"], mean, rtol=2e-5, atol=1e-6)
    np.testing.assert_array_equal(got["incompatible"], got["compatibility"] == 0)
    np.testing.assert_array_equal(got["episode"], demos.episode)
    np.testing.assert_array_equal(got["step"], demos.step)


@pytest.mark.parametrize("kind", ["mlp", "lstm"])
def test_streaming_equals_in_memory_for_any_chunk_size(policies, demos_file, tmp_path, kind):
    from elicit_jax.data.demos import read_demos

    demos = read_demos(demos_file)
    memory = score_demos(
        policies[kind], demos, ScoreConfig.from_preset("square-nut", chunk_size=1000)
    )
    for chunk in (3, 16, 85):
        out = tmp_path / f"s{chunk}.parquet"
        score_file(
            policies[kind], demos_file, out, ScoreConfig.from_preset("square-nut", chunk_size=chunk)
        )
        _, got = read_scores(out)
        for k in ("likelihood", "novelty", "compatibility", "prediction"):
            np.testing.assert_allclose(got[k], memory[k], rtol=1e-5, atol=1e-6, err_msg=k)
        np.testing.assert_array_equal(got["episode"], demos.episode)
        np.testing.assert_array_equal(got["operator"], demos.operator.astype(str))
        np.testing.assert_array_equal(got["success"], demos.success)
        # the file really was written in several row groups/batches
        assert pq.ParquetFile(out).metadata.num_rows == demos.n_steps


def test_headers_and_episode_summary(policies, demos_file, tmp_path):
    out = tmp_path / "scores.parquet"
    cfg = ScoreConfig(
        thresholds=Thresholds(0.05, 10.0, "given"), chunk_size=8
    )  # eta huge: every state familiar
    result = score_file(policies["mlp"], demos_file, out, cfg)
    header = read_header(out)
    assert header["kind"] == "scores"
    assert header["thresholds"] == {"lambda": 0.05, "eta": 10.0}
    assert header["config"]["likelihood"] == "ensemble-mean"
    assert header["inputs"]["demos"]["sha256"] == content_sha256(demos_file)
    ep_header = read_header(result.episodes_path)
    assert ep_header["kind"] == "episode-scores"
    assert result.episodes_path.name == "scores.episodes.parquet"
    _, pairs = read_scores(out)
    ep = result.episodes
    for i, e in enumerate(ep["episode"]):
        sel = pairs["episode"] == e
        n_inc = int(pairs["incompatible"][sel].sum())
        assert ep["length"][i] == sel.sum()
        assert ep["n_incompatible"][i] == n_inc
        assert ep["accepted"][i] == (n_inc <= 0.05 * sel.sum())
        assert ep["mean_compatibility"][i] == pytest.approx(pairs["compatibility"][sel].mean())
    # the in-memory summary agrees with the streamed one
    again = summarise_episodes(pairs, 0.05)
    np.testing.assert_array_equal(again["accepted"], ep["accepted"])
    table = pq.read_table(result.episodes_path)
    assert table.column("operator").to_pylist()[:2] == ["base", "op1"]


def test_dimension_mismatch_is_a_clear_error(policies, tmp_path):
    path = tmp_path / "d.parquet"
    write_demos(path, _demos(obs_dim=OBS + 1))
    with pytest.raises(ElicitError, match="obs_dim=6 but the policy expects obs_dim=5"):
        score_file(
            policies["mlp"], path, tmp_path / "s.parquet", ScoreConfig.from_preset("square-nut")
        )
    assert not (tmp_path / "s.parquet").exists()


def test_scoring_non_demos_artifact_fails(policies, tmp_path, demos_file):
    out = tmp_path / "s.parquet"
    score_file(
        policies["mlp"], demos_file, out, ScoreConfig.from_preset("square-nut", chunk_size=64)
    )
    with pytest.raises(ElicitError, match="expected demonstrations"):
        score_file(
            policies["mlp"], out, tmp_path / "t.parquet", ScoreConfig.from_preset("square-nut")
        )


def test_obs_field_mismatch_is_a_clear_error(policies, tmp_path):
    from elicit_jax.data.demos import fields_from_sizes

    demos = _demos()
    demos = dataclasses.replace(demos, obs_fields=fields_from_sizes([("pos", 3), ("goal", 2)]))
    path = tmp_path / "d.parquet"
    write_demos(path, demos)
    policy = policies["mlp"].replace(obs_fields=("pos", "vel"))
    with pytest.raises(ElicitError, match=r"obs fields \['pos', 'goal'\] but the policy"):
        score_file(policy, path, tmp_path / "s.parquet", ScoreConfig.from_preset("square-nut"))
    # same names in the same order: fine
    ok = policies["mlp"].replace(obs_fields=("pos", "goal"))
    score_file(
        ok, path, tmp_path / "s.parquet", ScoreConfig.from_preset("square-nut", chunk_size=64)
    )


def test_a_one_member_policy_earns_the_novelty_warning():
    from types import SimpleNamespace

    from elicit_jax.compat.score_file import one_member_note
    from elicit_jax.policy.kinds import model_kind

    def note(n: int, kind: str = "mlp", samples: int = 0) -> str | None:
        policy = SimpleNamespace(n_members=n, kind=kind, entry=model_kind(kind))
        return one_member_note(
            policy, ScoreConfig.from_preset("square-nut", dropout_samples=samples)
        )

    assert "novelty is 0 for every state" in note(1)
    assert note(5) is None  # an ensemble's members disagree
    assert note(1, kind="mdn") is None  # an MDN's own variance still varies
    assert note(1, samples=8) is None  # dropout samples stand in for members


def test_progress_is_told_the_pairs_and_advanced_through_all_of_them(
    policies, demos_file, tmp_path
):
    import contextlib

    import pyarrow.parquet as pq

    seen = []

    @contextlib.contextmanager
    def progress(total):
        seen.append(("total", total))
        yield lambda n: seen.append(("advance", n))
        seen.append(("closed", None))

    out = tmp_path / "s.parquet"
    score_file(
        policies["mlp"],
        demos_file,
        out,
        ScoreConfig.from_preset("square-nut", chunk_size=64),
        progress=progress,
    )
    rows = pq.ParquetFile(demos_file).metadata.num_rows
    steps = [n for what, n in seen if what == "advance"]
    assert seen[0] == ("total", rows) and seen[-1] == ("closed", None)
    assert sum(steps) == rows and len(steps) == -(-rows // 64)
