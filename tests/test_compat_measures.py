"""Compatibility measures: hand-computed ℓ, ν, M, the 5% rule, and property tests."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from elicit_jax.compat.measures import (
    PRESETS,
    ScoreConfig,
    compatibility,
    likelihood_error,
    novelty,
    rejects,
    score_pair,
)
from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.errors import ElicitError

# Two members, two action dims.
MEMBERS = jnp.array([[0.0, 1.0], [2.0, 3.0]])
ACTION = jnp.array([1.0, 0.0])


def test_likelihood_ensemble_mean_by_hand():
    # mean prediction = [1, 2]; diff to a = [0, 2]; squares [0, 4]; mean over dims = 2.0
    assert float(likelihood_error(MEMBERS, ACTION, "ensemble-mean")) == pytest.approx(2.0)


def test_likelihood_member_average_clips_by_hand():
    # clipped members: [[0, 1], [1, 1]]; clipped action [1, 0]
    # member 0: diffs [-1, 1] -> mean sq 1.0; member 1: diffs [0, 1] -> 0.5; average 0.75
    got = float(likelihood_error(MEMBERS, ACTION, "member-average", clip=1.0))
    assert got == pytest.approx(0.75)
    # without effective clipping (clip=10): member 0 diffs [-1, 1] -> 1; member 1 [1, 3] -> 5
    # average 3.0, which differs from the ensemble-mean 2.0 (mean of squares >= square of mean)
    assert float(likelihood_error(MEMBERS, ACTION, "member-average", clip=10.0)) == pytest.approx(
        3.0
    )


def test_novelty_both_std_conventions_by_hand():
    # per dim, members differ by 2: population std = 1, sample std (ddof 1) = sqrt(2)
    assert float(novelty(MEMBERS, ddof=0)) == pytest.approx(1.0)
    assert float(novelty(MEMBERS, ddof=1)) == pytest.approx(np.sqrt(2.0))


def test_compatibility_by_hand():
    # familiar (nu < eta): M = 1 - min(l / lambda, 1)
    assert float(compatibility(0.1, 0.01, 0.4, 0.05)) == pytest.approx(0.75)  # 1 - 0.25
    assert float(compatibility(0.4, 0.01, 0.4, 0.05)) == 0.0  # l = lambda: M = 0 (not flagged)
    assert float(compatibility(0.9, 0.01, 0.4, 0.05)) == 0.0  # capped at 0
    # novel (nu >= eta): M = 1 whatever l
    assert float(compatibility(0.9, 0.05, 0.4, 0.05)) == 1.0


def test_score_pair_and_mdn_spread():
    cfg = ScoreConfig(thresholds=Thresholds(4.0, 1.5, "given"))
    s = score_pair(MEMBERS, ACTION, jnp.float32(4.0), jnp.float32(1.5), cfg)
    # l = 2 (above), nu = 1 < 1.5 familiar -> M = 1 - 2/4 = 0.5
    assert float(s.likelihood) == pytest.approx(2.0)
    assert float(s.compatibility) == pytest.approx(0.5)
    assert not bool(s.incompatible)
    np.testing.assert_allclose(np.asarray(s.mean), [1.0, 2.0])
    # an MDN-style spread replaces the across-member std: mean([2, 4]) = 3 >= 1.5 -> novel
    s2 = score_pair(
        MEMBERS[:1], ACTION, jnp.float32(4.0), jnp.float32(1.5), cfg, jnp.array([2.0, 4.0])
    )
    assert float(s2.novelty) == pytest.approx(3.0)
    assert float(s2.compatibility) == 1.0
    # one member [0, 1] vs a = [1, 0]: l = mean([1, 1]) = 1
    assert float(s2.likelihood) == pytest.approx(1.0)


def test_five_percent_rule_by_hand():
    # 100 steps: 5 incompatible is exactly 5% -> accepted; 6 exceeds it -> rejected
    assert not rejects(5, 100)
    assert rejects(6, 100)
    # 90 steps: 5% = 4.5, so 4 accepted and 5 rejected
    assert not rejects(4, 90)
    assert rejects(5, 90)


def test_config_validation_and_presets():
    assert ScoreConfig.from_preset("round-nut").thresholds.lam == PRESETS["round-nut"][0] == 0.35
    assert ScoreConfig.from_preset("hammer-drawer").thresholds.eta == 0.06
    assert ScoreConfig.from_preset("round-nut").thresholds.source == "preset round-nut"
    for bad in ({"likelihood": "x"}, {"ddof": 2}):
        with pytest.raises(ElicitError):
            ScoreConfig.from_preset("square-nut", **bad)
    for lam, eta in ((0.0, 0.05), (0.4, -1.0), (True, 0.05), ("0.3", 0.05), (float("nan"), 1)):
        with pytest.raises(ElicitError):
            ScoreConfig(thresholds=Thresholds(lam, eta, "given"))
    # no silent task default: every caller says which thresholds it scores with
    with pytest.raises(TypeError, match="thresholds"):
        ScoreConfig()
    with pytest.raises(ElicitError, match="unknown preset"):
        ScoreConfig.from_preset("peg")


_vals = st.floats(0.0, 5.0, allow_nan=False)
_pos = st.floats(1e-3, 5.0, allow_nan=False)
_M = jax.jit(compatibility)


@settings(max_examples=200, deadline=None)
@given(ell=_vals, nu=_vals, lam=_pos, eta=_pos, lam2=_pos)
def test_compatibility_properties(ell, nu, lam, eta, lam2):
    m = float(_M(ell, nu, lam, eta))
    assert 0.0 <= m <= 1.0
    if nu >= eta:
        assert m == 1.0
    lo, hi = sorted((lam, lam2))
    assert float(_M(ell, nu, lo, eta)) <= float(_M(ell, nu, hi, eta)) + 1e-7


def test_pinned_to_the_original_codes_get_compatibility():
    """With member-average ℓ and the sample std, our ℓ, ν and decision match the original
    code's scoring (per member: clamp both actions to the action limit, mean squared error over
    dims, then the mean over members; novelty: the unbiased std across members, mean over
    dims; a pair counts as bad when ℓ > λ and ν < η). Numbers computed by hand below."""
    members = jnp.array([[0.5, -0.2], [1.4, 0.0], [0.2, 0.1]])
    action = jnp.array([0.8, -1.3])  # clamped to [0.8, -1.0]
    # clamped predictions [0.5,-0.2], [1.0,0.0], [0.2,0.1]:
    # (0.09 + 0.64)/2 = 0.365; (0.04 + 1.0)/2 = 0.52; (0.36 + 1.21)/2 = 0.785; mean 0.556667
    ell = likelihood_error(members, action, "member-average", clip=(-1.0, 1.0))
    assert float(ell) == pytest.approx(1.67 / 3, abs=1e-6)
    # unclamped predictions; dim 0 [0.5, 1.4, 0.2]: var (0.04 + 0.49 + 0.25)/2 = 0.39;
    # dim 1 [-0.2, 0, 0.1]: var 0.0466667/2; nu = (sqrt(0.39) + sqrt(0.0233333)) / 2
    nu = novelty(members, ddof=1)
    assert float(nu) == pytest.approx((np.sqrt(0.39) + np.sqrt(0.14 / 6)) / 2, abs=1e-6)
    cfg = ScoreConfig.from_preset("square-nut", likelihood="member-average", ddof=1)
    bad = score_pair(members, action, jnp.float32(0.5), jnp.float32(0.4), cfg, clip=(-1.0, 1.0))
    assert bool(bad.incompatible) and float(bad.compatibility) == 0.0  # 0.5567 > 0.5, 0.389 < 0.4
    ok = score_pair(members, action, jnp.float32(0.6), jnp.float32(0.4), cfg, clip=(-1.0, 1.0))
    assert not bool(ok.incompatible)
    assert float(ok.compatibility) == pytest.approx(1 - (1.67 / 3) / 0.6, abs=1e-6)
    # novel state (nu >= eta): never bad, M = 1
    novel = score_pair(members, action, jnp.float32(0.5), jnp.float32(0.3), cfg, clip=(-1.0, 1.0))
    assert not bool(novel.incompatible) and float(novel.compatibility) == 1.0


def test_member_average_clips_to_per_dim_bounds_by_hand():
    # bounds [-2, 2] on dim 0 and [-0.5, 0.5] on dim 1 (e.g. the demos' recorded bounds)
    members = jnp.array([[0.0, 0.9]])
    action = jnp.array([1.5, -0.3])
    low, high = jnp.array([-2.0, -0.5]), jnp.array([2.0, 0.5])
    # dim 0: 0 - 1.5 -> 2.25; dim 1: clip(0.9) = 0.5, 0.5 - (-0.3) = 0.8 -> 0.64; mean 1.445
    got = likelihood_error(members, action, "member-average", clip=(low, high))
    assert float(got) == pytest.approx(1.445)
    # a fixed ±1 clip would have given ((0 - 1)^2 + (0.9 + 0.3)^2) / 2 = 1.22
    assert float(likelihood_error(members, action, "member-average", clip=1.0)) == pytest.approx(
        1.22
    )


def test_action_scaling_by_hand():
    # training action std [0.5, 0 (constant), 2]: weights [2, left out, 0.5]
    weight = jnp.array([2.0, 0.0, 0.5])
    members = jnp.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    action = jnp.array([1.0, 0.0, 1.0])
    # mean prediction [0, 0, 0.5]; scaled errors [2, -, 0.25]; squares 4, 0.0625 over 2 dims
    assert float(likelihood_error(members, action, weight=weight)) == pytest.approx(4.0625 / 2)
    # unscaled: (1 + 0 + 0.25) / 3
    assert float(likelihood_error(members, action)) == pytest.approx(1.25 / 3)
    # novelty: per-dim std [0, 0, 0.5] -> scaled [0, -, 0.25] over 2 dims = 0.125
    assert float(novelty(members, 0, weight)) == pytest.approx(0.125)


def test_config_json_is_the_layout_pipelines_have_always_recorded():
    """Stage configs embed these dicts: a changed layout would re-run every cached stage."""
    from elicit_jax.compat.filtering import FilterConfig
    from elicit_jax.compat.measures import config_dict, config_from_dict

    cfg = ScoreConfig.from_preset("square-nut")
    d = config_dict(cfg)
    assert d == {
        "likelihood": "ensemble-mean", "ddof": 0, "lambda": 0.4, "eta": 0.05,
        "accept_fraction": 0.05, "chunk_size": 4096, "clip": None, "action_scale": "none",
        "dropout_samples": 0, "dropout_seed": 0,
    }  # fmt: skip
    back = config_from_dict(d, "preset square-nut")
    assert back == cfg and back.thresholds.source == "preset square-nut"
    assert FilterConfig().to_dict() == {
        "level": "pair", "method": "m", "pair_mode": "renumber", "lambda_": None, "eta": None,
        "accept_fraction": 0.05, "seed": 0,
    }  # fmt: skip
    given = FilterConfig(thresholds=Thresholds(0.3, 0.07, "given"))
    assert FilterConfig.from_dict(given.to_dict()).thresholds.pair == (0.3, 0.07)
