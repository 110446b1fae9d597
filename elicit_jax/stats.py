"""Seed statistics of success rates: paired t intervals and a two-level bootstrap.

Two questions, two tools.

**One collection, several training seeds** (:func:`paired_t_interval`,
:func:`welch_t_interval`; a study's report). Two policies of the study are compared
*paired*: the policy trained with seed s on one set and the policy trained with seed s on the
other, both evaluated on the same seeded initial states
(the evaluation uses one set of initial states for every policy). Per seed s the difference
d_s = success_a(s) − success_b(s) is a mean over those same rollouts, so rollout-to-rollout
variation of the initial states is shared and cancels in part; what remains is the variation
between training seeds (and the rollouts' binomial noise), which the spread of the d_s
measures directly.

The interval is Student's t over seeds: d̄ ± t(0.975, n − 1) · sd(d) / √n, sd with n − 1.
With 5 seeds t = 2.776, so the interval is wide — deliberately. A bootstrap over seeds would
resample from only 5 values (126 distinct resamples) and is known to under-cover at that
size; a bootstrap over rollouts would ignore the training-seed variation, which is the larger
noise here (a seed-to-seed std of 5-10 points against a rollout standard error of ~6 points
per 50 rollouts, which the d_s already contain). The t interval assumes the d_s roughly
normal, which a mean of 50 outcomes per policy makes reasonable. One seed gives no interval.

**Several collections, several training seeds each** (:func:`paired_difference`; the
phenomenon benchmark). A comparison of two training conditions (e.g. base-only vs. base + a new
operator's demos) varies with two kinds of seed: the *collection* seed (which demonstrations
were collected) and the *training* seed (network initialisation, minibatches, dropout). Both
conditions of one collection seed share its base demonstrations, so the natural unit is the
paired difference per collection seed: mean over training seeds of the new condition minus the
same for the reference. :func:`paired_difference` reports those differences, their mean and a
percentile bootstrap interval that resamples collection seeds and, within each, the training
seeds of each condition — so both sources of variation widen the interval.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

import numpy as np

from elicit_jax.errors import ElicitError

LEVEL = 0.95


@dataclasses.dataclass(frozen=True)
class PairedDiff:
    """Mean paired difference and its interval (same units as the inputs).

    Attributes:
      mean: mean of the per-seed differences.
      low: lower end of the interval (NaN with one seed).
      high: upper end.
      n: seeds paired.
    """

    mean: float
    low: float
    high: float
    n: int

    @property
    def no_spread(self) -> bool:
        """True when every seed's difference is the same, so the interval has no width: it
        then says nothing about noise (the rollouts' own noise is not in it)."""
        return self.n > 1 and interval_without_spread(self.low, self.high)

    @property
    def excludes_zero(self) -> bool:
        """True when the whole interval lies on one side of 0 (a difference beyond noise); never
        for an interval without spread (:attr:`no_spread`)."""
        return self.n > 1 and not self.no_spread and (self.low > 0 or self.high < 0)


def interval_without_spread(low: float, high: float) -> bool:
    """True when an interval has no width (every paired difference the same): it then
    measures no noise, so it never counts as excluding 0."""
    return abs(high - low) <= 1e-9


NO_SPREAD_NOTE = "no spread, not a test"


def sample_std(values: Sequence[float] | np.ndarray) -> float:
    """The spread every reported table uses: the sample std (ddof 1), 0.0 below two values.

    Args:
      values: the numbers (success rates of seeds, episode lengths, ...).

    Returns:
      ``std(values, ddof=1)``, or 0.0 for fewer than two values (no spread, never NaN).
    """
    v = np.asarray(values, np.float64)
    return float(v.std(ddof=1)) if v.size > 1 else 0.0


def t_quantile(df: float, level: float = LEVEL) -> float:
    """Two-sided Student t quantile ``t((1 + level) / 2, df)``."""
    from scipy.stats import t

    return float(t.ppf(0.5 + level / 2, df))


def paired_t_interval(a: Sequence[float], b: Sequence[float], level: float = LEVEL) -> PairedDiff:
    """Interval of mean(a − b) for values paired by position (one per training seed).

    Args:
      a: per-seed values of one policy.
      b: per-seed values of the other, same seeds in the same order.
      level: confidence level.
    """
    d = np.asarray(a, float) - np.asarray(b, float)
    if d.shape != (len(a),) or len(a) != len(b) or d.size == 0:
        raise ValueError(f"paired values need equal, non-empty lengths ({len(a)}, {len(b)})")
    n = int(d.size)
    mean = float(d.mean())
    if n == 1:
        return PairedDiff(mean, math.nan, math.nan, 1)
    half = t_quantile(n - 1, level) * float(d.std(ddof=1)) / math.sqrt(n)
    return PairedDiff(mean, mean - half, mean + half, n)


def welch_t_interval(a: Sequence[float], b: Sequence[float], level: float = LEVEL) -> PairedDiff:
    """Interval of mean(a) − mean(b) for two independent samples (Welch's t).

    For a difference from a reference measured on its own seeds (a study's people against the
    base policy): the standard error adds both samples' (sd² / n, sd with n − 1) and the
    degrees of freedom are Welch–Satterthwaite's. A ``b`` of one value has no spread to add.

    Args:
      a: one sample (e.g. each person's mean success over seeds).
      b: the other (e.g. the base policy's success per seed).
      level: confidence level.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.ndim != 1 or b.ndim != 1 or a.size == 0 or b.size == 0:
        raise ValueError(f"two non-empty samples needed ({a.size}, {b.size})")
    n = int(a.size)
    mean = float(a.mean() - b.mean())
    if n == 1:
        return PairedDiff(mean, math.nan, math.nan, 1)
    va = float(a.var(ddof=1)) / n
    vb = float(b.var(ddof=1)) / b.size if b.size > 1 else 0.0
    if va + vb == 0:
        return PairedDiff(mean, mean, mean, n)
    df = (va + vb) ** 2 / (va**2 / (n - 1) + (vb**2 / (b.size - 1) if b.size > 1 else 0.0))
    half = t_quantile(df, level) * math.sqrt(va + vb)
    return PairedDiff(mean, mean - half, mean + half, n)


def format_diff(diff: PairedDiff | None, scale: float = 100.0) -> str:
    """``+10.0 [−5.2, +25.2]`` in points (× ``scale``); ``*`` marks an interval excluding 0; a
    non-zero difference without spread over seeds says it is not a test."""
    if diff is None:
        return "–"
    m = diff.mean * scale
    if diff.n < 2:
        return f"{m:+.1f} (1 seed)"
    mark = " *" if diff.excludes_zero else ""
    if diff.no_spread and abs(m) >= 0.05:
        mark = f" (all {diff.n} seeds differ by the same: {NO_SPREAD_NOTE})"
    return f"{m:+.1f} [{diff.low * scale:+.1f}, {diff.high * scale:+.1f}]{mark}"


@dataclasses.dataclass(frozen=True)
class PairedDifference:
    """Difference ``new − reference`` of a success measure over collection seeds.

    Attributes:
      keys: collection seeds, in the order of ``per_key``.
      per_key: (C,) mean over training seeds of new minus that of reference, per collection seed.
      mean: mean of ``per_key``.
      low, high: percentile bootstrap interval of ``mean`` at ``level``.
      level: the interval's coverage (e.g. 0.95).
      n_boot: bootstrap resamples.
    """

    keys: tuple[int, ...]
    per_key: np.ndarray
    mean: float
    low: float
    high: float
    level: float
    n_boot: int

    @property
    def excludes_zero(self) -> bool:
        """The interval lies entirely above or entirely below 0."""
        return self.low > 0.0 or self.high < 0.0

    def describe(self, fmt: str = "{:+.1f}") -> str:
        """``"-9.3 [-14.0, -4.7]"``: the mean and its interval."""
        return f"{fmt.format(self.mean)} [{fmt.format(self.low)}, {fmt.format(self.high)}]"


def _matrix(values: Sequence[float], what: str, key: int) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 1 or arr.size == 0:
        raise ElicitError(f"collection seed {key}: {what} needs at least one training seed")
    if not np.all(np.isfinite(arr)):
        raise ElicitError(f"collection seed {key}: {what} has non-finite values")
    return arr


def paired_difference(
    new: Mapping[int, Sequence[float]],
    reference: Mapping[int, Sequence[float]],
    *,
    n_boot: int = 10_000,
    level: float = 0.95,
    seed: int = 0,
) -> PairedDifference:
    """Paired difference ``new − reference`` with a two-level percentile bootstrap.

    Args:
      new: collection seed -> per-training-seed values of the new condition.
      reference: collection seed -> per-training-seed values of the reference condition
        (same collection seeds; the number of training seeds may differ).
      n_boot: bootstrap resamples.
      level: coverage of the interval.
      seed: seed of the bootstrap's random generator (the result is deterministic).

    Each resample draws C collection seeds with replacement, then, within each drawn seed,
    the new condition's and the reference's training seeds with replacement (independently:
    a training seed of one condition is not paired with the same-numbered seed of the other,
    since their data differ), and averages the per-seed differences.

    Raises:
      ElicitError: different collection seeds, no collection seed, a condition without
        training seeds, non-finite values, ``n_boot < 1`` or ``level`` outside (0, 1).
    """
    if set(new) != set(reference):
        raise ElicitError(
            f"collection seeds differ: {sorted(new)} (new) vs {sorted(reference)} (reference)"
        )
    if not new:
        raise ElicitError("no collection seeds to compare")
    if n_boot < 1 or not 0.0 < level < 1.0:
        raise ElicitError(f"need n_boot >= 1 and 0 < level < 1, got {n_boot}, {level}")
    keys = tuple(sorted(new))
    a = [_matrix(new[k], "the new condition", k) for k in keys]
    b = [_matrix(reference[k], "the reference", k) for k in keys]
    per_key = np.array([x.mean() - y.mean() for x, y in zip(a, b, strict=True)])
    rng = np.random.default_rng(seed)
    c = len(keys)
    picks = rng.integers(0, c, (n_boot, c))
    boot = np.zeros(n_boot)
    for p in range(c):  # each drawn position resamples its training seeds afresh
        for j in range(c):
            rows = np.flatnonzero(picks[:, p] == j)
            ma = a[j][rng.integers(0, a[j].size, (rows.size, a[j].size))].mean(axis=1)
            mb = b[j][rng.integers(0, b[j].size, (rows.size, b[j].size))].mean(axis=1)
            boot[rows] += ma - mb
    boot /= c
    tail = (1.0 - level) / 2.0
    low, high = np.quantile(boot, [tail, 1.0 - tail])
    return PairedDifference(
        keys=keys,
        per_key=per_key,
        mean=float(per_key.mean()),
        low=float(low),
        high=float(high),
        level=level,
        n_boot=n_boot,
    )
