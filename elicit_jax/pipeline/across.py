"""The study over several collections: its headline cells pooled over collections, the
collection the unit of replication.

A cell's success varies with two seeds: the *collection* (which demonstrations a collection
happens to contain; ``[collections]``) and the *training* seed. Within a collection every
policy is trained with the same training seeds and evaluated on the same initial states, so a
cell is compared with Naive, Base or the random drop *paired*: d = success(cell, s) −
success(reference, s) per training seed s of a collection. Each collection's differences are
averaged, and :func:`~elicit_jax.stats.collections_interval` gives Student's t interval over
those collection means (df = collections − 1): the collections are the independent draws, so
they set the width, whatever the training seeds add inside each mean.

Each table tests many differences; their p-values are Holm-adjusted within the table
(:func:`~elicit_jax.stats.holm`) and ``*`` marks only an adjusted p-value below 0.05. How many
collections agree in sign is printed with its sign-test p-value, a description rather than
evidence (3 of 3 is p = 0.25).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from elicit_jax.pipeline.tables import (
    METHOD_LABELS,
    ReportData,
    ResultRow,
    Table,
    collections_of,
    mean_std,
)
from elicit_jax.stats import (
    CollectionsDiff,
    collections_interval,
    format_collections_diff,
    holm,
    tested,
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
    """One headline cell pooled over collections, with its differences from Naive and Base
    (and, for the M-filter, from the random drop of the same amount)."""

    task: str
    model: str
    method: str
    operator: str | None
    successes: tuple[float, ...]
    vs_naive: CollectionsDiff | None
    vs_base: CollectionsDiff | None
    vs_random: CollectionsDiff | None = None

    def diffs(self) -> tuple[CollectionsDiff | None, ...]:
        """The cell's differences in table-column order (− Naive, − Base, − Random filter)."""
        return (self.vs_naive, self.vs_base, self.vs_random)


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
            random = rows_of.get((task, model, "random", op), [])
            random = random if (task, model, "random", op) in everywhere else []
            for m in (m for m in METHOD_LABELS if (task, model, m, op) in everywhere):
                mine = rows_of[(task, model, m, op)]
                vs_naive = None if m == "naive" else _diff(mine, naive, colls)
                vs_random = _diff(mine, random, colls) if m == "filtered" else None
                out.append(
                    AcrossCell(
                        task, model, m, op, _succ(mine), vs_naive, _diff(mine, base, colls),
                        vs_random,
                    )
                )  # fmt: skip
    return out


def _succ(rows: Sequence[ResultRow]) -> tuple[float, ...]:
    return tuple(r.success for r in rows)


def adjusted_cells(
    cells: Sequence[AcrossCell],
) -> list[tuple[AcrossCell, tuple[float | None, ...]]]:
    """Each cell with the Holm-adjusted p-values of its differences (None where there is no
    difference), adjusted over every difference of the cells given (one table)."""
    family = [d.p for c in cells for d in c.diffs() if d is not None]
    adjusted = iter(holm(family))
    return [(c, tuple(None if d is None else next(adjusted) for d in c.diffs())) for c in cells]


def across_tables(data: ReportData) -> list[tuple[str, Table]]:
    """Per task × model, the cells run on every collection, pooled over collections: success
    mean (std) over (collection, training seed), and each cell's paired difference from
    Naive, from Base and (M-filter) from the random drop of the same amount, with Student's t
    interval over the collections' means and its Holm-adjusted p-value within the table.
    Empty for a single collection."""
    colls = collections_of(data.results)
    by_table: dict[tuple[str, str], list[AcrossCell]] = {}
    for c in across_cells(data):
        by_table.setdefault((c.task, c.model), []).append(c)
    out = []
    for (task, model), cells in by_table.items():
        with_random = any(c.vs_random is not None for c in cells)
        rows = []
        for c, (p_naive, p_base, p_random) in adjusted_cells(cells):
            row = [
                c.operator or "–",
                METHOD_LABELS[c.method],
                mean_std(c.successes),
                "" if c.vs_naive is None else format_collections_diff(c.vs_naive, adjusted=p_naive),
                "" if c.vs_base is None else format_collections_diff(c.vs_base, adjusted=p_base),
            ]
            if with_random:
                row.append(
                    ""
                    if c.vs_random is None
                    else format_collections_diff(c.vs_random, adjusted=p_random)
                )
            rows.append(row)
        header = ["operator", "training set", "success % mean (std)", "− Naive", "− Base"]
        if with_random:
            header.append("− Random filter (same amount)")
        m = tested([d.p for c in cells for d in c.diffs() if d is not None])
        out.append(
            (
                f"{task} — {model}: across {len(colls)} collections {colls} × training seeds: "
                "success % mean (std) over (collection, training seed); paired differences in "
                f"points [95% Student t interval over the {len(colls)} collections' means]; "
                f"Holm-adjusted over the {m} differences of this table, * only where the "
                "adjusted p < 0.05",
                (header, rows),
            )
        )
    return out


def across_note(data: ReportData) -> list[str]:
    """The report's statement of the across-collections interval and of sign agreement."""
    colls = collections_of(data.results)
    if len(colls) < 2:
        return []
    diffs = [d for c in across_cells(data) for d in c.diffs() if d is not None]
    unanimous = sum(d.agreeing == len(colls) for d in diffs)
    return [
        f"Across collections: every collection ({colls}) trains the same training seeds on its "
        "own demonstrations; a cell's difference from Naive, Base or the random drop is paired "
        "by training seed and initial states within a collection and averaged per collection. "
        "The collection is the unit of replication: the 95% interval is Student's t over the "
        f"{len(colls)} collections' means (df = {len(colls) - 1}), which keeps its coverage at "
        "any spread between collections (the training-seed and rollout noise are inside each "
        "mean). Within each table the t tests' p-values are Holm-adjusted over the table's "
        "differences, and * marks only an adjusted p-value below 0.05: an interval that "
        "excludes 0 without * is not a finding once the table's other tests are counted.",
        f"Sign agreement: in {unanimous} of {len(diffs)} paired differences all "
        f"{len(colls)} collections have the sign of the pooled mean. Each count is printed with "
        "its two-sided sign-test p-value, and is never evidence on its own: all "
        f"{len(colls)} of {len(colls)} agreeing is p = "
        f"{0.5 ** (len(colls) - 1):.3g} by chance alone.",
    ]
