"""Paired 95% intervals of a difference in success rate between two training sets.

Two policies of the study are compared *paired*: the policy trained with seed s on one set and
the policy trained with seed s on the other, both evaluated on the same seeded initial states
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
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

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
    def excludes_zero(self) -> bool:
        """True when the whole interval lies on one side of 0 (a difference beyond noise)."""
        return self.n > 1 and (self.low > 0 or self.high < 0)


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
    """``+10.0 [−5.2, +25.2]`` in points (× ``scale``); ``*`` marks an interval excluding 0."""
    if diff is None:
        return "–"
    m = diff.mean * scale
    if diff.n < 2:
        return f"{m:+.1f} (1 seed)"
    mark = " *" if diff.excludes_zero else ""
    return f"{m:+.1f} [{diff.low * scale:+.1f}, {diff.high * scale:+.1f}]{mark}"
