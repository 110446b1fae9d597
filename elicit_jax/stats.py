"""Seed statistics of success rates: paired t intervals, collection-level t intervals, Holm.

Three questions, three tools.

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

**Several collections, several training seeds each** (:func:`collections_interval`; a
study over ``[collections]``). A difference varies with two kinds of seed: the *collection*
(which demonstrations were collected) and the *training* seed. The collection is the unit of
replication: each collection's paired differences are averaged over its training seeds, and
the interval is Student's t over those C means (df = C − 1; t = 4.303 at 3 collections,
2.776 at 5). The training-seed and rollout noise are inside each mean, so nothing is counted
twice. A bootstrap that resamples 3 collections draws from 10 distinct multisets and
under-covers badly (tests/test_coverage.py shows it).

**Many differences in one table** (:func:`holm`). A report table tests 5-50 differences; at 95%
each, some exclude 0 by chance. Within a table the p-values of the t tests are adjusted by
Holm's step-down method, and ``*`` marks only a difference whose adjusted p-value is below
0.05. How many collections agree in sign is printed with its sign-test p-value
(:func:`sign_test_p`): with 3 collections unanimity is p = 0.25, never evidence on its own.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

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
      p: two-sided p-value of the t test of a zero mean (NaN with one seed or no spread):
        what a multiple-comparison adjustment (:func:`holm`) works on.
    """

    mean: float
    low: float
    high: float
    n: int
    p: float = math.nan

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
    se = float(d.std(ddof=1)) / math.sqrt(n)
    half = t_quantile(n - 1, level) * se
    return PairedDiff(mean, mean - half, mean + half, n, _p(mean, se, n - 1, half))


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
    return PairedDiff(mean, mean - half, mean + half, n, _p(mean, math.sqrt(va + vb), df, half))


def t_p_value(mean: float, se: float, df: float) -> float:
    """Two-sided p-value of Student's t test of a zero mean: ``2 · P(T_df > |mean| / se)``.

    NaN when there is nothing to test: no degrees of freedom, or no spread (``se`` 0).
    """
    from scipy.stats import t

    if not df > 0 or not se > 0 or not math.isfinite(se):
        return math.nan
    return float(min(1.0, 2.0 * t.sf(abs(mean) / se, df)))


def _p(mean: float, se: float, df: float, half: float) -> float:
    """The t test's p-value, NaN for an interval without spread (rounding leaves a spread of
    ~1e-17 between equal values: not a test, so not a member of a Holm family)."""
    return math.nan if interval_without_spread(-half, half) else t_p_value(mean, se, df)


def holm(pvalues: Sequence[float]) -> list[float]:
    """Holm's step-down adjustment of a family of p-values (family-wise error ≤ α).

    Sort the m finite p-values ascending; the i-th smallest (i from 1) is multiplied by
    m − i + 1, capped at 1 and made non-decreasing. A NaN (a difference that was not a test:
    one seed, no spread) stays NaN and does not count in m.

    Args:
      pvalues: the family, in any order.

    Returns:
      The adjusted p-values, in the input order.
    """
    p = np.asarray(pvalues, dtype=float)
    out = np.full(p.shape, math.nan)
    idx = np.flatnonzero(np.isfinite(p))
    m = idx.size
    running = 0.0
    for rank, k in enumerate(idx[np.argsort(p[idx], kind="stable")]):
        running = max(running, min(1.0, (m - rank) * float(p[k])))
        out[k] = running
    return [float(x) for x in out]


def holm_over(diffs: Sequence[PairedDiff | CollectionsDiff | None]) -> list[float | None]:
    """:func:`holm` over the p-values of one table's differences, aligned with ``diffs``
    (None where there is no difference)."""
    adjusted = iter(holm([d.p for d in diffs if d is not None]))
    return [None if d is None else next(adjusted) for d in diffs]


def tested(pvalues: Sequence[float]) -> int:
    """How many of ``pvalues`` are tests (finite): the m of :func:`holm`."""
    return int(np.isfinite(np.asarray(pvalues, dtype=float)).sum())


def sign_test_p(values: Sequence[float]) -> float:
    """Two-sided sign test: do the signs of ``values`` (one per collection) lean one way
    more than fair coins would? Zeros are dropped; NaN when nothing is left.

    3 of 3 in one direction gives 0.25 and 5 of 5 0.0625: agreement among this few
    collections is never evidence on its own.
    """
    from scipy.stats import binomtest

    v = np.asarray(values, dtype=float)
    pos, neg = int((v > 0).sum()), int((v < 0).sum())
    if pos + neg == 0:
        return math.nan
    return float(binomtest(max(pos, neg), pos + neg, 0.5).pvalue)


def format_p(p: float) -> str:
    """``0.034``, ``<0.001`` or ``–`` (NaN: not a test)."""
    if not math.isfinite(p):
        return "–"
    return "<0.001" if p < 0.001 else f"{p:.3f}"


def significant(excludes_zero: bool, adjusted: float | None, alpha: float = 1 - LEVEL) -> bool:
    """Whether a difference earns its ``*``: its interval excludes 0 and, when it is one of a
    family, its Holm-adjusted p-value (``adjusted``) is below ``alpha`` too."""
    if not excludes_zero:
        return False
    return adjusted is None or (math.isfinite(adjusted) and adjusted < alpha)


def format_diff(
    diff: PairedDiff | None, scale: float = 100.0, adjusted: float | None = None
) -> str:
    """``+10.0 [−5.2, +25.2]`` in points (× ``scale``); a non-zero difference without spread
    over seeds says it is not a test.

    Without ``adjusted``, ``*`` marks an interval excluding 0 (a lone comparison). With it
    (the difference's Holm-adjusted p-value in its table, :func:`holm`), the cell adds
    ``(Holm p 0.034)`` and ``*`` marks only an adjusted p-value below 0.05.
    """
    if diff is None:
        return "–"
    m = diff.mean * scale
    if diff.n < 2:
        return f"{m:+.1f} (1 seed)"
    mark = " *" if significant(diff.excludes_zero, adjusted) else ""
    if diff.no_spread and abs(m) >= 0.05:
        mark = f" (all {diff.n} seeds differ by the same: {NO_SPREAD_NOTE})"
    elif adjusted is not None and math.isfinite(diff.p):
        mark = f" (Holm p {format_p(adjusted)}){mark}"
    return f"{m:+.1f} [{diff.low * scale:+.1f}, {diff.high * scale:+.1f}]{mark}"


@dataclasses.dataclass(frozen=True)
class CollectionsDiff:
    """A paired difference pooled over collections, the collection the unit of replication.

    Attributes:
      mean: mean over collections of each collection's mean paired difference.
      low: lower end of the Student t interval over the collections' means (NaN with one
        collection).
      high: its upper end.
      p: two-sided p-value of that t test (NaN with one collection or no spread).
      per_collection: mean paired difference within each collection, in input order.
      n_pairs: (collection, training seed) differences behind the means.
      level: the interval's coverage.
    """

    mean: float
    low: float
    high: float
    p: float
    per_collection: tuple[float, ...]
    n_pairs: int
    level: float = LEVEL

    @property
    def no_spread(self) -> bool:
        """True when every collection's mean difference is the same: an interval of no width,
        which says nothing about noise."""
        return len(self.per_collection) > 1 and interval_without_spread(self.low, self.high)

    @property
    def excludes_zero(self) -> bool:
        """True when the whole interval lies on one side of 0; never without spread or with
        one collection."""
        return (
            len(self.per_collection) > 1 and not self.no_spread and (self.low > 0 or self.high < 0)
        )

    @property
    def agreeing(self) -> int:
        """Collections whose own mean difference has the sign of the pooled mean (0 counts
        as agreeing with 0 only)."""
        sign = np.sign(self.mean)
        return int(sum(np.sign(v) == sign for v in self.per_collection))

    @property
    def sign_p(self) -> float:
        """Two-sided sign-test p-value of the collections' signs (:func:`sign_test_p`)."""
        return sign_test_p(self.per_collection)


def collections_interval(
    diffs: Sequence[Sequence[float]], *, level: float = LEVEL
) -> CollectionsDiff:
    """Pooled difference and its Student t interval with the collection as the unit.

    Each collection's paired differences (one per training seed) are averaged first; the
    interval is ``mean ± t(df = C − 1) · sd / √C`` over those C means (sd with ddof 1). The
    collections are independent draws of the data, and within one the training seeds and
    rollouts only add noise to its mean, so the means are independent and (each a mean of
    many rollouts) close to normal: the interval keeps its coverage at any spread between
    collections (tests/test_coverage.py checks it at 3 and 5 collections).

    Args:
      diffs: per collection, the paired differences of its training seeds (cell − reference,
        one per training seed both have, evaluated on the same initial states).
      level: coverage of the interval.

    Returns:
      The mean of the collections' means, the interval, its p-value and each collection's
      mean. One collection gives no interval (NaN ends: the collection is the unit). Equal
      means give the interval ``[d, d]``, which :attr:`CollectionsDiff.no_spread` marks as
      not a test.

    Raises:
      ElicitError: no collection, a collection without differences, a non-finite difference
        or ``level`` outside (0, 1).
    """
    if not diffs:
        raise ElicitError("no collection to pool")
    if not 0.0 < level < 1.0:
        raise ElicitError(f"need 0 < level < 1, got {level}")
    arrays = [np.asarray(d, dtype=float) for d in diffs]
    for k, arr in enumerate(arrays):
        if arr.ndim != 1 or arr.size == 0:
            raise ElicitError(f"collection {k}: no paired training seed")
        if not np.all(np.isfinite(arr)):
            raise ElicitError(f"collection {k}: a paired difference is not finite")
    means = np.array([a.mean() for a in arrays])
    c = means.size
    mean = float(means.mean())
    low = high = p = math.nan
    if c > 1:
        se = float(means.std(ddof=1)) / math.sqrt(c)
        half = t_quantile(c - 1, level) * se
        low, high, p = mean - half, mean + half, _p(mean, se, c - 1, half)
    return CollectionsDiff(
        mean=mean,
        low=low,
        high=high,
        p=p,
        per_collection=tuple(float(m) for m in means),
        n_pairs=int(sum(a.size for a in arrays)),
        level=level,
    )


def format_collections_diff(
    diff: CollectionsDiff | None, scale: float = 100.0, adjusted: float | None = None
) -> str:
    """``+2.0 [−1.0, +5.0] (Holm p 0.412); 2/3 collections agree in sign (sign test p 1.000)``
    in points; ``*`` as :func:`format_diff` (only below an adjusted 0.05 when ``adjusted`` is
    given). The sign count is a description, never evidence on its own: its p-value says how
    weak it is."""
    if diff is None:
        return "–"
    k = len(diff.per_collection)
    mark = " *" if significant(diff.excludes_zero, adjusted) else ""
    if diff.no_spread and abs(diff.mean * scale) >= 0.05:
        mark = f" ({NO_SPREAD_NOTE})"
    elif adjusted is not None and math.isfinite(diff.p):
        mark = f" (Holm p {format_p(adjusted)}){mark}"
    signs = f"{diff.agreeing}/{k} collections agree in sign"
    if math.isfinite(diff.sign_p):
        signs += f" (sign test p {format_p(diff.sign_p)})"
    return (
        f"{diff.mean * scale:+.1f} [{diff.low * scale:+.1f}, {diff.high * scale:+.1f}]{mark}; "
        + signs
    )
