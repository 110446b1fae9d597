"""The study over several collections: its headline cells pooled over (collection, training
seed), with intervals that resample both.

A cell's success varies with two seeds: the *collection* (which demonstrations a collection
happens to contain; ``[collections]``) and the *training* seed. Within a collection every
policy is trained with the same training seeds and evaluated on the same initial states, so a
cell is compared with Naive or Base *paired*: d = success(cell, s) − success(reference, s) per
training seed s of a collection. :func:`collections_interval` pools those differences over
(collection, training seed) and gives a two-level percentile bootstrap interval: each draw
takes as many collections as there are, with replacement, then within each drawn collection
its training seeds with replacement (keeping each seed's pair together), and pools the drawn
differences. The draws come from a fixed seed, so the interval is deterministic.

With 3 collections the outer level resamples from 3 values (10 distinct multisets): the
interval is a description of the spread over the collections run, not a guarantee of coverage;
the report says so beside it, and counts how many collections agree in sign.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.tables import (
    METHOD_LABELS,
    ReportData,
    ResultRow,
    Table,
    collections_of,
    mean_std,
)
from elicit_jax.stats import NO_SPREAD_NOTE, interval_without_spread

N_BOOT = 10_000
BOOT_SEED = 0


@dataclasses.dataclass(frozen=True)
class CollectionsDiff:
    """A paired difference pooled over (collection, training seed), with its interval.

    Attributes:
      mean: mean of every (collection, training seed) paired difference.
      low: lower end of the two-level percentile bootstrap interval.
      high: its upper end.
      per_collection: mean paired difference within each collection, in input order.
      n_pairs: paired differences pooled.
      n_boot: bootstrap draws.
    """

    mean: float
    low: float
    high: float
    per_collection: tuple[float, ...]
    n_pairs: int
    n_boot: int

    @property
    def no_spread(self) -> bool:
        """True when every pooled difference is the same: an interval of no width, which
        says nothing about noise."""
        return self.n_pairs > 1 and interval_without_spread(self.low, self.high)

    @property
    def excludes_zero(self) -> bool:
        """True when the whole interval lies on one side of 0; never without spread."""
        return self.n_pairs > 1 and not self.no_spread and (self.low > 0 or self.high < 0)

    @property
    def agreeing(self) -> int:
        """Collections whose own mean difference has the sign of the pooled mean (0 counts
        as agreeing with 0 only)."""
        sign = np.sign(self.mean)
        return int(sum(np.sign(v) == sign for v in self.per_collection))


def collections_interval(
    diffs: Sequence[Sequence[float]],
    *,
    n_boot: int = N_BOOT,
    level: float = 0.95,
    seed: int = BOOT_SEED,
) -> CollectionsDiff:
    """Pooled mean and two-level percentile bootstrap interval of paired differences.

    Args:
      diffs: per collection, the paired differences of its training seeds (cell − reference,
        one per training seed both have, evaluated on the same initial states).
      n_boot: bootstrap draws.
      level: coverage of the interval.
      seed: seed of the draws (the result is deterministic).

    Returns:
      The pooled mean over (collection, training seed), the interval, and each collection's
      own mean. Every difference equal gives the interval ``[d, d]``; one collection resamples
      its training seeds only.

    Raises:
      ElicitError: no collection, a collection without differences, a non-finite difference,
        ``n_boot < 1`` or ``level`` outside (0, 1).
    """
    if not diffs:
        raise ElicitError("no collection to pool")
    if n_boot < 1 or not 0.0 < level < 1.0:
        raise ElicitError(f"need n_boot >= 1 and 0 < level < 1, got {n_boot}, {level}")
    arrays = [np.asarray(d, dtype=float) for d in diffs]
    for k, arr in enumerate(arrays):
        if arr.ndim != 1 or arr.size == 0:
            raise ElicitError(f"collection {k}: no paired training seed")
        if not np.all(np.isfinite(arr)):
            raise ElicitError(f"collection {k}: a paired difference is not finite")
    rng = np.random.default_rng(seed)
    c = len(arrays)
    picks = rng.integers(0, c, (n_boot, c))
    total, count = np.zeros(n_boot), np.zeros(n_boot)
    for slot in range(c):  # every drawn slot resamples its collection's seeds afresh
        for k, arr in enumerate(arrays):
            rows = np.flatnonzero(picks[:, slot] == k)
            drawn = arr[rng.integers(0, arr.size, (rows.size, arr.size))]
            total[rows] += drawn.sum(axis=1)
            count[rows] += arr.size
    boot = total / count
    tail = (1.0 - level) / 2.0
    low, high = np.quantile(boot, [tail, 1.0 - tail])
    pooled = np.concatenate(arrays)
    return CollectionsDiff(
        mean=float(pooled.mean()),
        low=float(low),
        high=float(high),
        per_collection=tuple(float(a.mean()) for a in arrays),
        n_pairs=int(pooled.size),
        n_boot=n_boot,
    )


def format_collections_diff(diff: CollectionsDiff | None, scale: float = 100.0) -> str:
    """``+2.0 [−1.0, +5.0]; 2/3 collections agree`` in points; ``*`` marks an interval that
    excludes 0."""
    if diff is None:
        return "–"
    k = len(diff.per_collection)
    mark = " *" if diff.excludes_zero else ""
    if diff.no_spread and abs(diff.mean * scale) >= 0.05:
        mark = f" ({NO_SPREAD_NOTE})"
    return (
        f"{diff.mean * scale:+.1f} [{diff.low * scale:+.1f}, {diff.high * scale:+.1f}]{mark}; "
        f"{diff.agreeing}/{k} collections agree in sign"
    )


def paired_by_collection(
    cell: Sequence[ResultRow], reference: Sequence[ResultRow], collections: Sequence[int]
) -> list[list[float]] | None:
    """Per collection, ``success(cell, s) − success(reference, s)`` over the training seeds
    both have; None when a collection has no common seed or a pair was evaluated on different
    initial states (not comparable)."""
    out = []
    for c in collections:
        ref = {r.seed: r for r in reference if r.collection == c}
        mine = sorted((r for r in cell if r.collection == c), key=lambda r: r.seed)
        pairs = [(r, ref[r.seed]) for r in mine if r.seed in ref]
        if not pairs or any(x.init_states != y.init_states for x, y in pairs):
            return None
        out.append([x.success - y.success for x, y in pairs])
    return out


def _diff(
    cell: Sequence[ResultRow], ref: Sequence[ResultRow], colls: list[int]
) -> CollectionsDiff | None:
    diffs = paired_by_collection(cell, ref, colls) if cell and ref else None
    return None if diffs is None else collections_interval(diffs)


@dataclasses.dataclass(frozen=True)
class AcrossCell:
    """One headline cell pooled over collections, with its differences from Naive and Base."""

    task: str
    model: str
    method: str
    operator: str | None
    successes: tuple[float, ...]
    vs_naive: CollectionsDiff | None
    vs_base: CollectionsDiff | None


def across_cells(data: ReportData) -> list[AcrossCell]:
    """The cells run on every collection (Base first per task × model), pooled; empty for a
    single collection."""
    colls = collections_of(data.results)
    if len(colls) < 2:
        return []
    rows_of: dict[tuple, list[ResultRow]] = {}
    for r in data.results:
        rows_of.setdefault((r.task, r.model, r.method, r.operator), []).append(r)
    everywhere = {k for k, rs in rows_of.items() if {r.collection for r in rs} == set(colls)}
    out = []
    for task, model in dict.fromkeys((r.task, r.model) for r in data.results):
        base = rows_of.get((task, model, "base", None), [])
        out.append(AcrossCell(task, model, "base", None, _succ(base), None, None))
        ops = dict.fromkeys(
            r.operator
            for r in data.results
            if (r.task, r.model) == (task, model)
            and r.operator
            and (task, model, r.method, r.operator) in everywhere
        )
        for op in ops:
            naive = rows_of.get((task, model, "naive", op), [])
            for m in (m for m in METHOD_LABELS if (task, model, m, op) in everywhere):
                mine = rows_of[(task, model, m, op)]
                vs_naive = None if m == "naive" else _diff(mine, naive, colls)
                out.append(
                    AcrossCell(task, model, m, op, _succ(mine), vs_naive, _diff(mine, base, colls))
                )
    return out


def _succ(rows: Sequence[ResultRow]) -> tuple[float, ...]:
    return tuple(r.success for r in rows)


def across_tables(data: ReportData) -> list[tuple[str, Table]]:
    """Per task × model, the cells run on every collection, pooled over (collection, training
    seed): success mean (std, ddof 1), and each cell's paired difference from Naive and from
    Base with its two-level bootstrap interval (:func:`collections_interval`). Empty for a
    single collection."""
    colls = collections_of(data.results)
    tables: dict[tuple[str, str], list[list[str]]] = {}
    for c in across_cells(data):
        row = [
            c.operator or "–",
            METHOD_LABELS[c.method],
            mean_std(c.successes),
            "" if c.method in ("base", "naive") else format_collections_diff(c.vs_naive),
            "" if c.method == "base" else format_collections_diff(c.vs_base),
        ]
        tables.setdefault((c.task, c.model), []).append(row)
    header = ["operator", "training set", "success % mean (std)", "− Naive", "− Base"]
    return [
        (
            f"{task} — {model}: across {len(colls)} collections {colls} × training seeds: "
            "success % mean (std) over (collection, training seed); paired differences in "
            f"points [95% two-level bootstrap interval, {N_BOOT} draws]",
            (header, rows),
        )
        for (task, model), rows in tables.items()
    ]


def across_note(data: ReportData) -> list[str]:
    """The report's statement of the across-collections interval and of sign agreement."""
    colls = collections_of(data.results)
    if len(colls) < 2:
        return []
    diffs = [d for c in across_cells(data) for d in (c.vs_naive, c.vs_base) if d is not None]
    unanimous = sum(d.agreeing == len(colls) for d in diffs)
    return [
        f"Across collections: every collection ({colls}) trains the same training seeds on its "
        "own demonstrations; a cell's difference from Naive or Base is paired by training seed "
        "and initial states within a collection and pooled over (collection, training seed). "
        f"Its 95% interval is a two-level percentile bootstrap ({N_BOOT} draws, seed "
        f"{BOOT_SEED}): draw {len(colls)} collections with replacement, then each drawn "
        "collection's training seeds with replacement. With this few collections the "
        "interval describes the spread over the collections run rather than promising "
        "coverage; * marks one that excludes 0.",
        f"Sign agreement: in {unanimous} of {len(diffs)} paired differences all "
        f"{len(colls)} collections have the sign of the pooled mean; a claim that holds in "
        "fewer depends on which demonstrations a collection happens to contain.",
    ]
