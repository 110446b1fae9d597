"""The report's table of the demos that conflict: per task (its sizes in the task label), demo
set, operator and collection, how many demos conflict with the base operator's way, each
measured from its own states (the ``conflicts`` column ``collect`` records on tasks that
measure episode traits, docs/operators.md), and their share.

With several collections every set has one row per collection and a row over all of them.
A contrast set collected with ``--require`` (the threshold fit's held-out base demos and
known-incompatible demos) kept only demos verified as required, so its share is what it was
kept for; its label says so. A run whose demos carry no such column has no rows, and its report
no table.
"""

from __future__ import annotations

from collections.abc import Sequence

from elicit_jax.pipeline.report_rows import ConflictRow, ReportData, Table, several_collections

ROLE_LABELS = {
    "base": "D_base",
    "new": "D_new",
    "holdout": "contrast: held-out base",
    "incompatible": "contrast: incompatible",
}
"""How the table names a demo set's role (:data:`elicit_jax.pipeline.plan.COLLECT_SEED_OFFSETS`
and ``new``)."""
REQUIRE_LABELS = {
    "conflicts": "kept only if conflicting",
    "no-conflict": "kept only if not conflicting",
}
"""What a set collected with ``--require`` adds to its label."""


def share(conflicting: int, demos: int) -> str:
    """``conflicting`` of ``demos`` as a percentage with one decimal (``–`` of no demos)."""
    return f"{100.0 * conflicting / demos:.1f}%" if demos else "–"


def _set_label(role: str, require: str) -> str:
    label = ROLE_LABELS.get(role, role or "–")
    return f"{label} ({REQUIRE_LABELS.get(require, require)})" if require else label


def _lines(rows: Sequence[ConflictRow], several: bool) -> list[tuple[str, int, int]]:
    """(collection, demos, conflicting) of one set: per collection, then over all of them."""
    if not several:
        return [("", r.n_demos, r.n_conflicts) for r in rows]
    rows = sorted(rows, key=lambda r: r.collection)
    out = [(str(r.collection), r.n_demos, r.n_conflicts) for r in rows]
    if len(rows) > 1:
        out.append(("all", sum(r.n_demos for r in rows), sum(r.n_conflicts for r in rows)))
    return out


def conflict_tables(data: ReportData) -> list[tuple[str, Table]]:
    """The table of the demos that conflict, titled; empty when no demo set measured it."""
    if not data.conflicts:
        return []
    sets: dict[tuple[str, str, str, str], list[ConflictRow]] = {}
    for r in data.conflicts:
        sets.setdefault((r.task, r.role, r.operator, r.require), []).append(r)
    several = several_collections(data.conflicts)
    rows = []
    for (task, role, operator, require), mine in sets.items():
        label = _set_label(role, require)
        for collection, demos, conflicting in _lines(mine, several):
            where = [collection] if several else []
            counts = [str(demos), str(conflicting), share(conflicting, demos)]
            rows.append([task, label, operator, *where, *counts])
    where = ["collection"] if several else []
    header = ["task", "demo set", "operator", *where, "demos", "conflicting", "share"]
    title = (
        "Demos that conflict with the base operator's way, each measured from its own states "
        "(column `conflicts`, recorded by collect)"
    )
    return [(title, (header, rows))]
