"""Feature statistics the way LeRobot computes them for a dataset (LeRobot 0.4 and later).

Per episode and numeric feature: ``min``, ``max``, ``mean``, ``std`` (population), ``count``
and the quantiles ``q01``, ``q10``, ``q50``, ``q90``, ``q99``. The quantiles are LeRobot's
histogram estimate, not exact order statistics: each dimension's values are counted into
:data:`QUANTILE_BINS` equal bins spanning ``[min - 1e-10, max + 1e-10]``, and the quantile
``q`` is read off the first bin whose cumulative count reaches ``q * count``, interpolated
linearly inside that bin (the lower edge of the range when the first bin already reaches it).
Arithmetic runs in the feature's dtype promoted to at least float32, as LeRobot's does, so a
dataset exported here normalises exactly as one LeRobot recorded itself. An episode of one
frame gets quantiles equal to its mean.

Dataset statistics aggregate the episodes': min of mins, max of maxes, count-weighted mean,
pooled variance, and count-weighted means of the episodes' quantiles (LeRobot's aggregation;
not the quantiles of the pooled frames).

Scalar features (shape ``(1,)``) keep shape ``(1,)`` statistics; vectors ``(d,)``; cameras
``(3, 1, 1)`` (carried over from the source dataset, never computed here).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
QUANTILE_BINS = 5000
EDGE_PAD = 1e-10
Stats = dict[str, np.ndarray]


def quantile_key(q: float) -> str:
    """``0.01 -> 'q01'``, ``0.5 -> 'q50'`` (the stats key LeRobot uses)."""
    return f"q{int(q * 100):02d}"


QUANTILE_KEYS = tuple(quantile_key(q) for q in QUANTILES)


def _column_quantiles(x: np.ndarray) -> list[float]:
    """Histogram quantiles of one dimension ``x: (N,)`` (N >= 2), one per :data:`QUANTILES`."""
    lo, hi = x.min(), x.max()
    edges = np.linspace(lo - EDGE_PAD, hi + EDGE_PAD, QUANTILE_BINS + 1)
    counts = np.cumsum(np.histogram(x, bins=edges)[0].astype(np.float64))
    out = []
    for q in QUANTILES:
        target = q * len(x)
        i = int(np.searchsorted(counts, target))
        if i == 0:
            out.append(edges[0])
        elif i >= len(counts):
            out.append(edges[-1])
        else:
            before, inside = counts[i - 1], counts[i] - counts[i - 1]
            if inside == 0:
                out.append(edges[i])
            else:
                out.append(edges[i] + (target - before) / inside * (edges[i + 1] - edges[i]))
    return out


def feature_stats(values: np.ndarray) -> Stats:
    """Statistics of one feature over one episode.

    Args:
      values: ``(N,)`` for a scalar feature or ``(N, d)`` for a vector feature.

    Returns:
      ``min, max, mean, std, q01 ... q99`` of shape ``(1,)`` or ``(d,)``, and ``count (1,)``.
    """
    values = np.asarray(values)
    x = values.reshape(len(values), -1)
    x = x.astype(np.result_type(x.dtype, np.float32), copy=False)
    n = len(x)
    if n < 2:
        mean = x.mean(0)
        stats = {"min": x.min(0), "max": x.max(0), "mean": mean, "std": x.std(0)}
        stats.update({k: mean.copy() for k in QUANTILE_KEYS})
    else:
        mean = x.mean(0)
        var = (x**2).mean(0) - mean**2
        stats = {"min": x.min(0), "max": x.max(0), "mean": mean, "std": np.sqrt(np.maximum(0, var))}
        per_dim = np.array([_column_quantiles(x[:, d]) for d in range(x.shape[1])])
        stats.update({k: per_dim[:, i] for i, k in enumerate(QUANTILE_KEYS)})
    stats["count"] = np.array([n])
    return stats


def aggregate_stats(per_episode: Sequence[Mapping[str, np.ndarray]]) -> Stats:
    """One feature's dataset statistics from its per-episode statistics (see module doc).

    Quantile keys are aggregated when every episode has them.
    """
    if not per_episode:
        raise ValueError("no statistics to aggregate")
    variances = np.stack([np.asarray(s["std"]) ** 2 for s in per_episode])  # in their dtype
    eps = [{k: np.asarray(v, np.float64) for k, v in s.items()} for s in per_episode]
    means = np.stack([s["mean"] for s in eps])
    counts = np.stack([s["count"] for s in eps])
    total = counts.sum(0)
    w = counts.reshape(counts.shape + (1,) * (means.ndim - counts.ndim))
    mean = (means * w).sum(0) / total
    var = ((variances + (means - mean) ** 2) * w).sum(0) / total
    out = {
        "min": np.min(np.stack([s["min"] for s in eps]), axis=0),
        "max": np.max(np.stack([s["max"] for s in eps]), axis=0),
        "mean": mean,
        "std": np.sqrt(var),
        "count": total.astype(np.int64),
    }
    for key in QUANTILE_KEYS:
        if all(key in s for s in eps):
            out[key] = (np.stack([s[key] for s in eps]) * w).sum(0) / total
    return out


def to_json(stats: Mapping[str, Mapping[str, np.ndarray]]) -> dict[str, dict[str, list]]:
    """Feature -> stats as nested lists (the layout of ``meta/stats.json``)."""
    return {f: {k: np.asarray(v).tolist() for k, v in s.items()} for f, s in stats.items()}


def from_json(stats: Mapping[str, Mapping[str, object]]) -> dict[str, Stats]:
    """Inverse of :func:`to_json`: nested lists to arrays."""
    return {f: {k: np.atleast_1d(np.asarray(v)) for k, v in s.items()} for f, s in stats.items()}
