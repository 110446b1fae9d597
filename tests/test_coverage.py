"""Do the report's intervals keep their promised 95%? A simulation at the sizes the studies use.

A study's paired difference (cell − reference) is made of: a true difference δ shared by every
collection; each collection's own departure from it (spread between collections, 0-20
points, normal); each (training seed, condition)'s departure of the success probability
(training-seed noise, 5 points); and the binomial noise of 50 rollouts. The report's two
intervals are checked on it:

- pooled over collections (:func:`elicit_jax.stats.collections_interval`, Student t over the
  collections' means), at 3 and 5 collections × 3 training seeds; its target is δ;
- within one collection (:func:`elicit_jax.stats.paired_t_interval`, Student t over training
  seeds), at 3 and 5 seeds; its target is that collection's own difference.

Each must contain its target in at least 93% of 1,500 simulated studies (a true 95% falls
below 93% with probability ~2e-4 per setting). A zero-width interval ("no spread, not a
test") counts as covering only if it sits exactly on the target. The checker is shown to fail
planted weak intervals: the two-level percentile bootstrap over collections and seeds that the
reports used before (it resamples 3 collections: 10 distinct draws), a normal (z) interval over
collection means, and a percentile bootstrap over 3 training seeds. Pure numpy and scipy.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import pytest

from elicit_jax.stats import collections_interval, paired_t_interval

SIMS = 1_500
FLOOR = 0.93
SEED_SD = 0.05
ROLLOUTS = 50

Interval = Callable[[Sequence[np.ndarray]], tuple[float, float]]


def _success(rng: np.random.Generator, p: np.ndarray) -> np.ndarray:
    p = np.clip(p, 0.0, 1.0)
    return rng.binomial(ROLLOUTS, p) / ROLLOUTS


def simulate(
    rng: np.random.Generator,
    *,
    collections: int,
    seeds: int,
    delta: float,
    spread: float,
    seed_sd: float = SEED_SD,
    base: float = 0.5,
    sims: int = SIMS,
) -> tuple[np.ndarray, np.ndarray]:
    """``sims`` studies: paired differences (sims, collections, seeds) and each collection's
    true difference (sims, collections), the target of the within-collection interval.

    The two conditions sit symmetrically around ``base``, so the probabilities stay inside
    (0, 1) (the clip is a guard that almost never acts: the target is computed from the same
    clipped probabilities' expectation only when it does not)."""
    own = delta + rng.normal(0.0, spread, (sims, collections))
    shape = (sims, collections, seeds)
    p_ref = base - own[..., None] / 2 + rng.normal(0.0, seed_sd, shape)
    p_new = base + own[..., None] / 2 + rng.normal(0.0, seed_sd, shape)
    assert np.mean((p_ref < 0) | (p_ref > 1) | (p_new < 0) | (p_new > 1)) < 1e-3
    return _success(rng, p_new) - _success(rng, p_ref), own


def coverage(interval: Interval, diffs: np.ndarray, target: np.ndarray) -> float:
    """Share of simulated studies whose interval contains its target (``low ≤ target ≤
    high``; a zero-width interval covers only its own point)."""
    hits = 0
    for study, truth in zip(diffs, target, strict=True):
        low, high = interval(list(study))
        hits += bool(low <= truth <= high)
    return hits / len(diffs)


def pooled_t(study: Sequence[np.ndarray]) -> tuple[float, float]:
    d = collections_interval(study)
    return d.low, d.high


def seeds_t(seeds: Sequence[float]) -> tuple[float, float]:
    d = paired_t_interval(list(seeds), [0.0] * len(seeds))
    return d.low, d.high


# --- planted weak intervals: each must fail the same check -------------------------------


def old_two_level_bootstrap(study: Sequence[np.ndarray], n_boot: int = 1_000):
    """The interval the reports printed before: draw C collections with replacement, then
    each drawn collection's training seeds with replacement, pool, take percentiles."""
    rng = np.random.default_rng(0)
    arr = np.asarray(study)  # (C, S): every collection has the same seeds here
    c, s = arr.shape
    picks = rng.integers(0, c, (n_boot, c))
    seeds = rng.integers(0, s, (n_boot, c, s))
    boot = arr[picks[..., None], seeds].mean(axis=(1, 2))
    low, high = np.quantile(boot, [0.025, 0.975])
    return float(low), float(high)


def z_over_collections(study: Sequence[np.ndarray]) -> tuple[float, float]:
    """Normal quantile instead of t: too narrow at 3 collections."""
    means = np.array([a.mean() for a in study])
    half = 1.96 * means.std(ddof=1) / np.sqrt(means.size)
    return means.mean() - half, means.mean() + half


def seeds_bootstrap(seeds: Sequence[float], n_boot: int = 1_000) -> tuple[float, float]:
    """Percentile bootstrap over 3 training seeds (10 distinct resamples)."""
    rng = np.random.default_rng(0)
    v = np.asarray(seeds, dtype=float)
    boot = v[rng.integers(0, v.size, (n_boot, v.size))].mean(axis=1)
    low, high = np.quantile(boot, [0.025, 0.975])
    return float(low), float(high)


# --- the checks ---------------------------------------------------------------------------


@pytest.mark.parametrize("collections", [3, 5])
@pytest.mark.parametrize("spread", [0.0, 0.05, 0.10, 0.20])
@pytest.mark.parametrize("delta", [0.0, 0.15])
def test_the_pooled_interval_keeps_its_coverage(collections, spread, delta):
    rng = np.random.default_rng(1000 * collections + int(100 * spread) + int(100 * delta))
    diffs, _ = simulate(rng, collections=collections, seeds=3, delta=delta, spread=spread)
    target = np.full(len(diffs), delta)
    assert coverage(pooled_t, diffs, target) >= FLOOR


@pytest.mark.parametrize("seeds", [3, 5])
@pytest.mark.parametrize("seed_sd", [0.0, 0.05, 0.10])
@pytest.mark.parametrize("delta", [0.0, 0.15])
def test_the_per_collection_interval_keeps_its_coverage(seeds, seed_sd, delta):
    rng = np.random.default_rng(7 + seeds + int(100 * seed_sd) + int(100 * delta))
    diffs, own = simulate(
        rng, collections=1, seeds=seeds, delta=delta, spread=0.10, seed_sd=seed_sd
    )
    assert coverage(lambda s: seeds_t(s[0]), diffs, own[:, 0]) >= FLOOR


def test_the_checker_fails_the_old_pooled_bootstrap_and_a_z_interval():
    """The planted weak intervals, at the spread between collections these studies show
    (~10 points): the check above would fail on them."""
    rng = np.random.default_rng(11)
    diffs, _ = simulate(rng, collections=3, seeds=3, delta=0.0, spread=0.10, sims=600)
    target = np.zeros(len(diffs))
    old = coverage(old_two_level_bootstrap, diffs, target)
    assert old < FLOOR - 0.05, old  # ~0.84: 1 null study in 6 "beyond the noise"
    assert coverage(z_over_collections, diffs, target) < FLOOR
    assert coverage(pooled_t, diffs, target) >= FLOOR  # the same studies, the new interval


def test_the_checker_fails_a_bootstrap_over_three_training_seeds():
    rng = np.random.default_rng(12)
    diffs, own = simulate(rng, collections=1, seeds=3, delta=0.0, spread=0.0, sims=600)
    assert coverage(lambda s: seeds_bootstrap(s[0]), diffs, own[:, 0]) < FLOOR


def test_identical_collections_give_no_claim_not_a_false_one():
    """No spread and no noise: every collection's difference the same. The interval has no
    width, covers only its own point, and never counts as excluding 0."""
    same = collections_interval([[0.1, 0.1, 0.1]] * 3)
    assert same.low == same.high == pytest.approx(0.1)
    assert same.no_spread and not same.excludes_zero and np.isnan(same.p)
    zero = collections_interval([[0.0] * 3] * 5)
    assert coverage(pooled_t, np.zeros((1, 5, 3)), np.zeros(1)) == 1.0
    assert zero.no_spread and not zero.excludes_zero
