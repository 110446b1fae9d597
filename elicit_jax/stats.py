"""Seed statistics of success rates: paired differences and a two-level bootstrap.

A comparison of two training conditions (e.g. base-only vs. base + a new operator's demos)
varies with two kinds of seed: the *collection* seed (which demonstrations were collected) and
the *training* seed (network initialisation, minibatches, dropout). Both conditions of one
collection seed share its base demonstrations, so the natural unit is the paired difference
per collection seed: mean over training seeds of the new condition minus the same for the
reference. :func:`paired_difference` reports those differences, their mean and a percentile
bootstrap interval that resamples collection seeds and, within each, the training seeds of
each condition — so both sources of variation widen the interval.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import numpy as np

from elicit_jax.errors import ElicitError


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
