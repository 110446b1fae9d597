"""Success of a condition and paired differences between conditions, from
:class:`~elicit_jax.pipeline.elicitation.gather.StudyData`.

Success of a condition (the paper's Table 2 cells): per training seed, the mean over the
population of each person's policy success (best checkpoint per seed, 50 rollouts), then
mean (std) over seeds (sample std, ddof 1, as the filtering report). Differences between two
conditions are paired by person: each person's difference of mean success over seeds, with
the pipeline's paired 95% Student t interval
(:func:`~elicit_jax.stats.paired_t_interval`), here over people — the person is the
unit a user study replicates; the training-seed noise enters through each person's mean.
A difference from the base policy (one policy per seed, no person) is Welch's t over the
people's means and the base policy's seeds. The differences of one table are a family: their
p-values are Holm-adjusted together (:func:`study_differences`), and ``*`` needs the adjusted
p-value below 0.05.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from elicit_jax.pipeline.elicitation.gather import StudyData
from elicit_jax.stats import (
    PairedDiff,
    format_diff,
    holm_over,
    paired_t_interval,
    welch_t_interval,
)

CONDITION_LABELS = {
    "base": "Base",
    "naive": "Naive",
    "filtered": "Naive + M-filtered",
    "informed": "Informed",
    "rejection": "Rejection, no adaptation",
    "prompt": "Prompt only",
    "indicator": "Live indicator only",
    "feedback": "Post-hoc feedback only",
    "naive-dagger": "Naive HG-DAgger",
    "informed-dagger": "Informed HG-DAgger",
}


def diff_text(diff: PairedDiff | None, adjusted: float | None = None) -> str:
    """A paired difference in points, ``+10.0 [−5.2, +25.2] (Holm p 0.210)``, as
    :func:`~elicit_jax.stats.format_diff` writes it (``*`` only where the Holm-adjusted p-value
    ``adjusted`` is below 0.05); one person: no interval."""
    if diff is None:
        return "–"
    if diff.n < 2:
        return f"{100 * diff.mean:+.1f} (1 person, no interval)"
    return format_diff(diff, adjusted=adjusted)


def study_differences(
    data: StudyData,
) -> list[tuple[str, str, str, str, PairedDiff | None, float | None]]:
    """Every ``(task, model, a, b, a − b, Holm-adjusted p)`` of :data:`DIFFERENCES`, the family
    of the study's Table 2: adjusted together, so neither the table nor the report's verdicts
    call a difference real that is one of many tests."""
    cells = success_cells(data)
    keys = [(t, m, a, b) for t, m in cells_of(data) for a, b in DIFFERENCES]
    diffs = [compare(cells, *k) for k in keys]
    return [(*k, d, p) for k, d, p in zip(keys, diffs, holm_over(diffs), strict=True)]


def success_cells(data: StudyData) -> dict[tuple, dict[int, float]]:
    """``(task, model, condition, person or None) -> {seed: success}``."""
    out: dict[tuple, dict[int, float]] = {}
    for r in data.results:
        out.setdefault((r.task, r.model, r.method, r.operator), {})[r.seed] = r.success
    return out


def cells_of(data: StudyData) -> list[tuple[str, str]]:
    """(task, model) pairs, in the order the study ran them."""
    seen = [(r.task, r.model) for r in data.results] + [(s.task, s.model) for s in data.sessions]
    return list(dict.fromkeys(seen))


def people_of(data: StudyData, task: str, model: str) -> list[str]:
    ids = {s.person for s in data.sessions if (s.task, s.model) == (task, model)}
    ids |= {r.operator for r in data.results if (r.task, r.model) == (task, model) and r.operator}
    return sorted(ids, key=lambda p: int(p[1:]) if p[1:].isdigit() else 0)


def population_by_seed(
    cells: Mapping[tuple, Mapping[int, float]], task: str, model: str, cond: str, people: list[str]
) -> dict[int, float]:
    """Per seed, the mean success over the people with a result for that seed."""
    if cond == "base":
        return dict(cells.get((task, model, "base", None), {}))
    per_seed: dict[int, list[float]] = {}
    for p in people:
        for seed, value in cells.get((task, model, cond, p), {}).items():
            per_seed.setdefault(seed, []).append(value)
    return {s: float(np.mean(v)) for s, v in sorted(per_seed.items())}


def person_means(
    cells: Mapping[tuple, Mapping[int, float]], task: str, model: str, cond: str
) -> dict[str, float]:
    """Each person's mean success over seeds (base: the same value for everyone)."""
    out = {}
    for (t, m, c, p), by_seed in cells.items():
        if (t, m, c) == (task, model, cond) and p is not None and by_seed:
            out[p] = float(np.mean(list(by_seed.values())))
    return out


def compare(
    cells: Mapping[tuple, Mapping[int, float]], task: str, model: str, a: str, b: str
) -> PairedDiff | None:
    """``a − b`` in success (fraction), paired by person; None when no person has both.

    ``b = "base"``: the people's mean against the base policy's mean over its seeds, Welch's
    t over the people and the base seeds (:func:`~elicit_jax.stats.welch_t_interval`),
    so the base policy's own seed noise widens the interval."""
    ma = person_means(cells, task, model, a)
    if b == "base":
        base = cells.get((task, model, "base", None), {})
        if not base or not ma:
            return None
        return welch_t_interval(list(ma.values()), list(base.values()))
    mb = person_means(cells, task, model, b)
    common = sorted(set(ma) & set(mb))
    if not common:
        return None
    return paired_t_interval([ma[p] for p in common], [mb[p] for p in common])


# The differences the study reports, ``(a, b)`` for ``a − b``: the paper's two claims (naive
# data hurts, informed data helps), what the M-filter adds, and teaching apart from filtering:
# what the 5% rule's rejections alone do, and what the interface adds beyond them.
DIFFERENCES = (
    ("naive", "base"),
    ("informed", "naive"),
    ("filtered", "naive"),
    ("informed", "base"),
    ("rejection", "naive"),
    ("informed", "rejection"),
)
