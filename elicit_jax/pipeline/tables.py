"""Report content: the tables of results built from :class:`ReportData`.

The ``*_table(s)`` functions turn the data into ``(header, rows)`` tables in the paper's
layout, which :mod:`elicit_jax.pipeline.report` renders: success per policy, paired
differences, model comparison, λ sensitivity, rollout lengths. With several collections
(``[collections]``) each collection gets its own results and difference tables; the pooled
table is :mod:`elicit_jax.pipeline.across`'s. The tables of fits, filters and curation are in
:mod:`elicit_jax.pipeline.tables_fit`; the rows in :mod:`elicit_jax.pipeline.report_rows`
(both re-exported here for the modules that read them from this one).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Iterator, Sequence

import numpy as np

from elicit_jax.pipeline.report_rows import (
    METHOD_LABELS,
    CurationRow,
    FilterRow,
    LambdaPoint,
    LengthRow,
    ReportData,
    ResultRow,
    Table,
    ThresholdRow,
    task_label,
)
from elicit_jax.pipeline.tables_fit import (
    curation_table,
    decisions_table,
    filter_table,
    length_table,
    threshold_table,
    trust_text,
)
from elicit_jax.stats import PairedDiff, format_diff, holm, paired_t_interval, tested

__all__ = [
    "METHOD_LABELS",
    "CurationRow",
    "FilterRow",
    "LambdaPoint",
    "LengthRow",
    "ReportData",
    "ResultRow",
    "Table",
    "ThresholdRow",
    "curation_table",
    "decisions_table",
    "difference_tables",
    "filter_table",
    "length_table",
    "mean_std",
    "models_table",
    "results_tables",
    "rollout_length_table",
    "sensitivity_tables",
    "threshold_table",
    "trust_text",
]

INTERVAL_NOTE = (
    "95% interval of the difference, paired by training seed and initial states (every policy "
    "is evaluated on the same seeded initial states): Student's t over the per-seed differences "
    "(see docs/pipelines.md). Each table of differences adjusts its p-values for the number "
    "of differences it tests (Holm), prints the adjusted p-value beside each interval, and "
    "marks with * only an adjusted p-value below 0.05 (its interval then excludes 0 too)."
)


STD_NOTE = (
    "Every std in these tables is the sample standard deviation (ddof = 1), the same "
    "convention as the intervals; a single value shows no spread (–)."
)


def mean_std(values: Sequence[float], scale: float = 100.0) -> str:
    """``mean (std)`` of ``values × scale``, one decimal; sample std over seeds (ddof = 1, as
    the intervals beside it, :data:`STD_NOTE`).

    One value gives ``mean (–)``: a single seed has no spread.
    """
    arr = np.asarray(values, dtype=float) * scale
    if arr.size == 0:
        return "–"
    if arr.size == 1:
        return f"{arr[0]:.1f} (–)"
    return f"{arr.mean():.1f} ({arr.std(ddof=1):.1f})"


def selection_label(results: Sequence[ResultRow]) -> str:
    """How the tables' checkpoints were chosen, in a few words for a table title."""
    rules = {r.selection for r in results}
    if rules == {"heldout"}:
        return "checkpoint per seed chosen on held-out rollouts"
    if rules == {"reported"}:
        return "best checkpoint per seed on the reported rollouts: biased upwards"
    if rules == {"single"}:
        return "the one checkpoint evaluated per seed"
    return "checkpoint per seed: mixed selection rules, see above"


def _cells(results: Sequence[ResultRow]) -> dict[tuple, list[float]]:
    out: dict[tuple, list[float]] = {}
    for r in sorted(results, key=lambda r: r.seed):
        out.setdefault((r.task, r.model, r.method, r.operator), []).append(r.success)
    return out


def collections_of(results: Sequence[ResultRow]) -> list[int]:
    """The collections ``results`` come from, in the order they first appear."""
    return list(dict.fromkeys(r.collection for r in results))


def per_collection(data: ReportData) -> list[tuple[str, ReportData]]:
    """``data`` cut by collection, each with a title prefix (none for a single collection)."""
    colls = collections_of(data.results)
    if len(colls) <= 1:
        return [("", data)]
    return [
        (
            f"collection {c}: ",
            dataclasses.replace(data, results=tuple(r for r in data.results if r.collection == c)),
        )
        for c in colls
    ]


def results_tables(data: ReportData) -> list[tuple[str, Table]]:
    """One table per (collection ×) task × model in the paper's layout: rows = operators,
    columns = methods.

    The first row is the base policy (D_base only); each operator row gives π_new trained on
    D_base ∪ D_new (Naive) and on the filtered D_new (M-Filtered, baselines), as success
    rate % mean (std) over seeds.
    """
    return [(pre + t, table) for pre, d in per_collection(data) for t, table in _results(d)]


def _results(data: ReportData) -> list[tuple[str, Table]]:
    cells = _cells(data.results)
    out = []
    for task, model, methods, ops in _grid(data.results, cells):
        header = ["operator", *[METHOD_LABELS[m] for m in methods]]
        base = mean_std(cells.get((task, model, "base", None), []))
        rows = [[f"base only: {base}", *["" for _ in methods]]]
        for op in ops:
            rows.append([op, *[mean_std(cells.get((task, model, m, op), [])) for m in methods]])
        out.append(
            (
                f"{task} — {model}: success % ({selection_label(data.results)}), "
                "mean (std) over seeds",
                (header, rows),
            )
        )
    return out


def _grid(
    results: Sequence[ResultRow], keys: Iterable[tuple]
) -> Iterator[tuple[str, str, list[str], list[str]]]:
    """Each task × model of ``results`` (in order of appearance) with its methods (in
    :data:`METHOD_LABELS` order, ``base`` aside) and operators (in the order of ``keys``),
    among result keys (task, model, method, operator)."""
    keys = list(keys)
    for task, model in dict.fromkeys((r.task, r.model) for r in results):
        mine = [k for k in keys if k[:2] == (task, model)]
        methods = [m for m in METHOD_LABELS if m != "base" and any(k[2] == m for k in mine)]
        yield task, model, methods, list(dict.fromkeys(k[3] for k in mine if k[3] is not None))


def paired_diff(a: Sequence[ResultRow], b: Sequence[ResultRow]) -> PairedDiff | None:
    """Paired interval of success(a) − success(b) over the seeds both have; None when there is
    no common seed or a pair was evaluated on different initial states (not comparable)."""
    by_seed = {r.seed: r for r in b}
    pairs = [(r, by_seed[r.seed]) for r in sorted(a, key=lambda r: r.seed) if r.seed in by_seed]
    if not pairs or any(x.init_states != y.init_states for x, y in pairs):
        return None
    return paired_t_interval([x.success for x, _ in pairs], [y.success for _, y in pairs])


def _rows(results: Sequence[ResultRow]) -> dict[tuple, list[ResultRow]]:
    out: dict[tuple, list[ResultRow]] = {}
    for r in results:
        out.setdefault((r.task, r.model, r.method, r.operator), []).append(r)
    return out


FROM_BASE = ("filtered", "filtered-episode", "filtered-valley")


def difference_tables(data: ReportData) -> list[tuple[str, Table]]:
    """Beside each results table: every cell's difference from Naive with its paired 95%
    interval (the Naive column: Naive − Base, does adding this operator's data help?), then
    the M-filters' differences from Base (the paper's claim: filtered ≥ base)."""
    return [(pre + t, table) for pre, d in per_collection(data) for t, table in _differences(d)]


def _differences(data: ReportData) -> list[tuple[str, Table]]:
    rows_of = _rows(data.results)
    out = []
    for task, model, methods, ops in _grid(data.results, rows_of):
        base = rows_of.get((task, model, "base", None), [])
        columns = [(m, "base" if m == "naive" else "naive") for m in methods]
        columns += [(m, "base") for m in FROM_BASE if m in methods and base]
        if "filtered" in methods and "random" in methods:
            columns.append(("filtered", "random"))  # which pairs, not how many
        diffs = []
        for op in ops:
            refs = {r: rows_of.get((task, model, r, op), []) for r in ("naive", "random")}
            refs["base"] = base
            for m, ref in columns:
                mine = rows_of.get((task, model, m, op), [])
                diffs.append(paired_diff(mine, refs[ref]) if mine and refs[ref] else None)
        cells = holm_cells(diffs)
        rows = [[op, *cells[k * len(columns) : (k + 1) * len(columns)]] for k, op in enumerate(ops)]
        header = ["operator", *[f"{METHOD_LABELS[m]} − {METHOD_LABELS[r]}" for m, r in columns]]
        what = "difference from Naive" if any(r == "naive" for _, r in columns) else "Naive − Base"
        if any(r == "base" and m != "naive" for m, r in columns):
            what += " (M-filters also from Base)"
        if ("filtered", "random") in columns:
            what += ", M-Filtered − Random filter (the same amount dropped at random)"
        out.append((f"{task} — {model}: {what}, points ({holm_title(diffs)})", (header, rows)))
    return out


def holm_cells(diffs: Sequence[PairedDiff | None]) -> list[str]:
    """The cells of one table's differences, each with its p-value Holm-adjusted over the
    table (``–`` where there is none)."""
    adjusted = iter(holm([d.p for d in diffs if d is not None]))
    return ["–" if d is None else format_diff(d, adjusted=next(adjusted)) for d in diffs]


def holm_title(diffs: Sequence[PairedDiff | None]) -> str:
    """What a table of differences says of its intervals and its ``*``."""
    m = tested([d.p for d in diffs if d is not None])
    return (
        f"paired 95% interval; Holm-adjusted over the {m} differences of this table, * only "
        "where the adjusted p < 0.05"
    )


def models_table(data: ReportData) -> list[tuple[str, Table]]:
    """Per task with several models: rows = base + operators, columns = models (Naive); the
    first collection's."""
    data = per_collection(data)[0][1]
    cells = _cells(data.results)
    out = []
    for task in dict.fromkeys(r.task for r in data.results):
        models = list(dict.fromkeys(r.model for r in data.results if r.task == task))
        if len(models) < 2:
            continue
        ops = list(
            dict.fromkeys(
                r.operator for r in data.results if r.task == task and r.method == "naive"
            )
        )
        rows = [
            [
                "Base (D_base only)",
                *[mean_std(cells.get((task, m, "base", None), [])) for m in models],
            ]
        ]
        for op in ops:
            rows.append(
                [
                    f"Naive + {op}",
                    *[mean_std(cells.get((task, m, "naive", op), [])) for m in models],
                ]
            )
        out.append((f"{task}: model comparison, success % mean (std)", (["", *models], rows)))
    return out


def sensitivity_tables(data: ReportData) -> list[tuple[str, Table]]:
    """Per task × model: held-out success of Base, Naive and M-Filtered at each λ point, with
    the paired interval of each point's difference from Naive."""
    rows_of = _rows(data.heldout)
    out = []
    for task, model in dict.fromkeys((r.task, r.model) for r in data.heldout):
        pts = sorted(
            (p for p in data.lambda_points if (p.task, p.model) == (task, model)),
            key=lambda p: p.point,
        )
        by_point: dict[tuple, list[ResultRow]] = {}
        for r in data.heldout:
            if (r.task, r.model, r.method) == (task, model, "filtered"):
                by_point.setdefault((r.operator, r.point), []).append(r)
        base = rows_of.get((task, model, "base", None), [])
        header = [
            "operator",
            "Naive",
            *[f"λ = {p.lambda_:.4g}" for p in pts],
        ]
        rows = [[f"base only: {mean_std([r.success for r in base])}", "", *["" for _ in pts]]]
        ops = list(
            dict.fromkeys(
                r.operator
                for r in data.heldout
                if r.operator and (r.task, r.model) == (task, model)
            )
        )
        means, diffs = [], []
        for op in ops:
            naive = rows_of.get((task, model, "naive", op), [])
            means.append(mean_std([r.success for r in naive]))
            diffs.append(paired_diff(naive, base) if naive and base else None)
            for p in pts:
                mine = by_point.get((op, p.point), [])
                means.append(mean_std([r.success for r in mine]))
                diffs.append(paired_diff(mine, naive) if mine and naive else None)
        texts = holm_cells(diffs)
        width = len(pts) + 1
        for k, op in enumerate(ops):
            at = slice(k * width, (k + 1) * width)
            (first, *rest) = zip(means[at], texts[at], strict=True)
            cells = [f"{first[0]}; vs Base {first[1]}", *[f"{m}; Δ {t}" for m, t in rest]]
            rows.append([op, *cells])
        seeds = sorted({r.seed for r in data.heldout if (r.task, r.model) == (task, model)})
        lo_hi = f"{pts[0].low:.4g} .. {pts[0].high:.4g}, fitted {pts[0].fitted:.4g}" if pts else "?"
        title = (
            f"{task} — {model}: λ sensitivity across the fitted margin (λ {lo_hi}); held-out "
            f"training seeds {seeds} and initial states; success % mean (std), Δ from Naive "
            f"({holm_title(diffs)})"
        )
        out.append((title, (header, rows)))
    return out


def rollout_length_table(data: ReportData) -> Table:
    """Mean rollout length (steps, until success or the horizon) per policy over seeds, and
    the checkpoint selected for each seed."""
    groups: dict[tuple, list[ResultRow]] = {}
    multi = len(collections_of(data.results)) > 1
    for r in sorted(data.results, key=lambda r: (r.task, r.model, r.operator or "", r.seed)):
        task = task_label(r.task, r.collection, multi)
        groups.setdefault((task, r.model, r.method, r.operator), []).append(r)
    header = [
        "task",
        "model",
        "operator",
        "training set",
        "mean rollout length",
        "selected checkpoint per seed (epoch; best: lowest validation loss)",
    ]
    rows = [
        [
            t,
            m,
            op or "–",
            METHOD_LABELS.get(meth, meth),
            f"{np.mean([r.mean_length for r in rs]):.1f}",
            ", ".join(f"s{r.seed}: {r.checkpoint}" for r in rs),
        ]
        for (t, m, meth, op), rs in groups.items()
    ]
    return header, rows
