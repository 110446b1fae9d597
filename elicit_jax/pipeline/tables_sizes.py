"""The report's table of a run at several named sizes (:mod:`elicit_jax.pipeline.sizes`),
side by side: per task, model and operator, at each sizes, D_base and D_new's counts, Base,
Naive and Naive − Base with its interval.

Read across a row's sizes it tells two readings apart: if Naive − Base is positive at every
sizes, extra data help whoever gave them (the base policy is data-starved); if it is negative
at some sizes, there the operator's data cost more than they add — the title claims no
direction in D_new's share, which the counts column gives. A sizes whose counts for
a task equal the default's trained the same policies: its row shows them, marked ``= default``.
"""

from __future__ import annotations

from collections.abc import Sequence

from elicit_jax.pipeline.across import paired_by_collection
from elicit_jax.pipeline.report_rows import ReportData, ResultRow, Table
from elicit_jax.pipeline.sizes import DEFAULT_SIZES, report_sizes, sizes_line, unsized_task
from elicit_jax.pipeline.tables import collections_of, mean_std, paired_diff
from elicit_jax.stats import (
    CollectionsDiff,
    PairedDiff,
    collections_interval,
    format_collections_diff,
    format_diff,
    holm,
    tested,
)

SAME = object()
"""A row whose policies are the default sizes' (the same counts): shown, not tested twice."""


def sizes_note(data: ReportData) -> list[str]:
    """The report's statement of the sizes run (none for the default sizes alone)."""
    sizes = report_sizes(data.configs)
    return [sizes_line(list(sizes), sizes)] if sizes else []


def sizes_heading(data: ReportData) -> str:
    """What the report's heading adds for named sizes (nothing for the default alone)."""
    sizes = report_sizes(data.configs)
    return f"; sizes {', '.join(sizes)}" if sizes else ""


def sizes_tables(data: ReportData) -> list[tuple[str, Table]]:
    """The side-by-side table of a run at several sizes; empty for one sizes."""
    sizes = report_sizes(data.configs)
    if len(sizes) < 2:
        return []
    rows_of: dict[tuple, list[ResultRow]] = {}
    for r in data.results:
        key = (unsized_task(r.task, r.sizes), r.model, r.method, r.operator, r.sizes)
        rows_of.setdefault(key, []).append(r)
    lines, diffs = [], []
    for task, model in dict.fromkeys((k[0], k[1]) for k in rows_of):
        ops = dict.fromkeys(k[3] for k in rows_of if k[:2] == (task, model) and k[3])
        for op in ops:
            for name, counts in sizes.items():
                if task not in counts:
                    continue
                same = counts[task] == sizes.get(DEFAULT_SIZES, {}).get(task)
                own = (task, model, "base", None, name) in rows_of
                source = DEFAULT_SIZES if same and not own else name
                base = rows_of.get((task, model, "base", None, source), [])
                naive = rows_of.get((task, model, "naive", op, source), [])
                b, n = counts[task]
                label = f"{name} (= default)" if source != name else name
                lines.append([task, model, op, label, f"{b} + {n}", mean_std(_succ(base)),
                              mean_std(_succ(naive))])  # fmt: skip
                diffs.append(SAME if source != name else _naive_minus_base(naive, base))
    if not lines:
        return []
    family = [d.p for d in diffs if d is not None and d is not SAME]
    adjusted = iter(holm(family))
    for line, d in zip(lines, diffs, strict=True):
        if d is SAME:
            line.append("as default (the same policies)")
        elif d is None:
            line.append("–")
        elif isinstance(d, CollectionsDiff):
            line.append(format_collections_diff(d, adjusted=next(adjusted)))
        else:
            line.append(format_diff(d, adjusted=next(adjusted)))
    header = ["task", "model", "operator", "sizes", "D_base + D_new", "Base", "Naive",
              "Naive − Base"]  # fmt: skip
    title = (
        "Sizes side by side: success % mean (std) of Base and Naive at each sizes, and Naive − "
        "Base in points [paired 95% interval; over the collections' means when there are "
        f"several]; Holm-adjusted over the {tested(family)} differences of this table, * only "
        "where the adjusted p < 0.05. Positive at every sizes: extra data help whoever gave "
        "them; negative at a sizes: there the operator's data cost more than they add"
    )
    return [(title, (header, lines))]


def _succ(rows: Sequence[ResultRow]) -> list[float]:
    return [r.success for r in sorted(rows, key=lambda r: (r.collection, r.seed))]


def _naive_minus_base(
    naive: Sequence[ResultRow], base: Sequence[ResultRow]
) -> PairedDiff | CollectionsDiff | None:
    """Naive − Base: paired by training seed, pooled over collections when there are several
    (the collection the unit of replication, as :mod:`elicit_jax.pipeline.across`)."""
    if not naive or not base:
        return None
    colls = collections_of(base)
    if len(colls) > 1:
        diffs = paired_by_collection(naive, base, colls)
        return None if diffs is None else collections_interval(diffs)
    return paired_diff(naive, base)
