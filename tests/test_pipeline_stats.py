"""Paired intervals of differences from Naive, checked against hand-computed numbers."""

from __future__ import annotations

import math

import pytest

from elicit_jax.pipeline.tables import (
    CurationRow,
    ReportData,
    ResultRow,
    curation_table,
    difference_tables,
    paired_diff,
)
from elicit_jax.stats import (
    format_diff,
    paired_t_interval,
    t_quantile,
    welch_t_interval,
)


def test_t_interval_by_hand():
    # d = (0.1, 0.1, 0.2, -0.1, 0.2): mean 0.1, sd (n - 1) = sqrt(0.06 / 4) = 0.122474,
    # se = 0.122474 / sqrt(5) = 0.0547723, t(0.975, 4) = 2.776445 -> half 0.152072
    d = paired_t_interval([0.5, 0.6, 0.7, 0.4, 0.6], [0.4, 0.5, 0.5, 0.5, 0.4])
    assert t_quantile(4) == pytest.approx(2.776445, abs=1e-6)
    assert (d.mean, d.n) == (pytest.approx(0.1), 5)
    assert d.low == pytest.approx(0.1 - 0.152072, abs=1e-6)
    assert d.high == pytest.approx(0.1 + 0.152072, abs=1e-6)
    assert not d.excludes_zero
    assert format_diff(d) == "+10.0 [-5.2, +25.2]"


def test_welch_interval_adds_the_reference_spread():
    # one reference value: the one-sample t interval of a − 0.5 (a: .6, .7, .8 → sd .1)
    one = welch_t_interval([0.6, 0.7, 0.8], [0.5])
    assert one.mean == pytest.approx(0.2)
    assert one.high - one.mean == pytest.approx(4.3027 * 0.1 / math.sqrt(3), rel=1e-4)
    # equal spreads and sizes: se √(2 × .01 / 3), df = 4 → t(0.975, 4) = 2.7764
    two = welch_t_interval([0.6, 0.7, 0.8], [0.4, 0.5, 0.6])
    assert two.high - two.mean == pytest.approx(2.7764 * math.sqrt(0.02 / 3), rel=1e-4)
    assert not one.excludes_zero and welch_t_interval([0.8, 0.9, 1.0], [0.1]).excludes_zero
    assert math.isnan(welch_t_interval([0.6], [0.4, 0.5]).low)


def test_interval_excluding_zero_is_marked_and_one_seed_has_none():
    # d = (0.10, 0.20, 0.18): mean 0.16, sd 0.0529150, se 0.0305505, t(0.975, 2) = 4.302653
    # -> half 0.131448
    d = paired_t_interval([0.50, 0.56, 0.56], [0.40, 0.36, 0.38])
    assert d.low == pytest.approx(0.16 - 0.131448, abs=1e-6)
    assert d.excludes_zero and format_diff(d) == "+16.0 [+2.9, +29.1] *"
    one = paired_t_interval([0.5], [0.3])
    assert math.isnan(one.low) and not one.excludes_zero
    assert format_diff(one) == "+20.0 (1 seed)" and format_diff(None) == "–"
    with pytest.raises(ValueError):
        paired_t_interval([0.1, 0.2], [0.1])


def _row(method, op, seed, success, states="A"):
    return ResultRow("t", "mlp", method, op, seed, success, 100.0, 50, "best", states)


def test_pairing_uses_common_seeds_and_refuses_different_initial_states():
    a = [_row("filtered", "x", s, v) for s, v in ((0, 0.5), (1, 0.7), (2, 0.6))]
    b = [_row("naive", "x", s, v) for s, v in ((1, 0.5), (2, 0.4), (3, 0.9))]
    d = paired_diff(a, b)  # seeds 1 and 2: d = (0.2, 0.2)
    assert d.n == 2 and d.mean == pytest.approx(0.2) and d.low == pytest.approx(0.2)
    b[0] = _row("naive", "x", 1, 0.5, states="B")
    assert paired_diff(a, b) is None
    assert paired_diff(a, [_row("naive", "x", 9, 0.5)]) is None


def test_difference_table_naive_against_base_and_methods_against_naive():
    rows = [_row("base", None, s, v) for s, v in enumerate((0.40, 0.36, 0.38))]
    rows += [_row("naive", "x", s, v) for s, v in enumerate((0.50, 0.56, 0.56))]
    rows += [_row("filtered", "x", s, v) for s, v in enumerate((0.52, 0.50, 0.54))]
    data = ReportData("p", "cpu", "", ".", "", tuple(rows))
    ((title, (header, body)),) = difference_tables(data)
    assert header == ["operator", "Naive − Base", "M-Filtered − Naive", "M-Filtered − Base"]
    # filtered - naive: d = (0.02, -0.06, -0.02), mean -0.02, sd 0.04, half 0.099367
    # filtered - base: d = (0.12, 0.14, 0.16), mean 0.14, sd 0.02, half 4.3027 * 0.02 / √3
    # Holm over the table's 3 tests: p 0.0067 × 3 = 0.020, 0.0345 × 2 = 0.069, 0.478 × 1. Naive
    # − Base's interval excludes 0 on its own, but not once the table's other tests count.
    assert body == [
        [
            "x",
            "+16.0 [+2.9, +29.1] (Holm p 0.069)",
            "-2.0 [-11.9, +7.9] (Holm p 0.478)",
            "+14.0 [+9.0, +19.0] (Holm p 0.020) *",
        ]
    ]
    assert title == (
        "t — mlp: difference from Naive (M-filters also from Base), points (paired 95% "
        "interval; Holm-adjusted over the 3 differences of this table, * only where the "
        "adjusted p < 0.05)"
    )
    only_naive = ReportData(
        "p", "cpu", "", ".", "", tuple(r for r in rows if r.method != "filtered")
    )
    ((title, (header, _)),) = difference_tables(only_naive)
    assert header == ["operator", "Naive − Base"]
    assert title == (
        "t — mlp: Naive − Base, points (paired 95% interval; Holm-adjusted over the 1 "
        "differences of this table, * only where the adjusted p < 0.05)"
    )


def test_every_filtering_table_compares_the_m_filter_with_the_random_drop():
    rows = [_row("base", None, s, v) for s, v in enumerate((0.40, 0.36, 0.38))]
    rows += [_row("naive", "x", s, v) for s, v in enumerate((0.20, 0.26, 0.22))]
    rows += [_row("filtered", "x", s, v) for s, v in enumerate((0.52, 0.50, 0.54))]
    rows += [_row("random", "x", s, v) for s, v in enumerate((0.24, 0.22, 0.30))]
    data = ReportData("p", "cpu", "", ".", "", tuple(rows))
    ((title, (header, body)),) = difference_tables(data)
    assert header[-1] == "M-Filtered − Random filter"
    assert "M-Filtered − Random filter (the same amount dropped at random)" in title
    # d = (0.28, 0.28, 0.24): mean 0.2667, sd 0.023094, half 4.302653 · 0.023094 / √3
    assert body[0][-1].startswith("+26.7 [+20.9, +32.4] (Holm p ")
    assert "over the 5 differences" in title  # N − B, M − N, R − N, M − B and M − R


def test_curation_table_says_when_demo_score_is_no_better_than_chance():
    rep = {
        "checkpoints": [{"epoch": 25, "successes": 54, "rollouts": 100}],
        "chosen_train_epoch": 25,
        "validation_epoch": 100,
    }
    rows = [
        CurationRow(
            "t",
            "mlp",
            "demo-score",
            op,
            (0.55, 0.56),
            0.55,
            True,
            rep | {"validation_balanced_accuracy": acc},
        )
        for op, acc in (("x", 0.5), ("y", 0.87))
    ]
    data = ReportData("p", "cpu", "", ".", "", (), curation=tuple(rows))
    _, body = curation_table(data)
    assert "rollout balanced accuracy 0.50 (no better than chance" in body[0][-1]
    assert "balanced accuracy 0.87" in body[1][-1] and "chance" not in body[1][-1]


def test_a_difference_without_spread_over_seeds_is_not_called_beyond_the_noise():
    # the phenomenon's square-nut collection 0: base 32, 20, 34 and same-style 82, 70, 84
    d = paired_t_interval([0.82, 0.70, 0.84], [0.32, 0.20, 0.34])
    assert d.mean == pytest.approx(0.5) and d.no_spread and not d.excludes_zero
    assert format_diff(d) == (
        "+50.0 [+50.0, +50.0] (all 3 seeds differ by the same: no spread, not a test)"
    )
    same = paired_t_interval([0.4, 0.5], [0.4, 0.5])  # identical policies: exactly no difference
    assert same.no_spread and format_diff(same) == "+0.0 [+0.0, +0.0]"


def test_the_study_verdicts_never_call_a_difference_real_that_holm_does_not(tmp_path):
    """Planted: informed − naive excludes 0 on its own (p ≈ 0.03 over 4 people), but it is one
    of the study table's 3 tests (Holm: ≈ 0.09); the generated prose must not call it real."""
    import dataclasses

    from elicit_jax.pipeline.elicitation.report import _verdicts
    from elicit_jax.pipeline.elicitation.success import study_differences
    from tests.test_report_rebuild import _study

    naive = {"p0": 0.2, "p1": 0.8, "p2": 0.4, "p3": 0.6}
    lift = {"p0": 0.05, "p1": 0.15, "p2": 0.10, "p3": 0.20}
    rows = [ResultRow("t", "mlp", "base", None, s, v, 50.0, 50, "best") for s, v in
            enumerate((0.5, 0.45, 0.55))]  # fmt: skip
    for p, v in naive.items():
        rows.append(ResultRow("t", "mlp", "naive", p, 0, v, 50.0, 50, "best"))
        rows.append(ResultRow("t", "mlp", "informed", p, 0, v + lift[p], 50.0, 50, "best"))
    data = dataclasses.replace(_study(tmp_path), results=tuple(rows), sessions=())
    family = {(a, b): (d, adj) for *_, a, b, d, adj in study_differences(data) if d}
    d, adjusted = family[("informed", "naive")]
    assert d.excludes_zero and d.p < 0.05 and adjusted == pytest.approx(3 * d.p)
    assert adjusted > 0.05 and len(family) == 3
    (line,) = [v for v in _verdicts(data) if "Informed − Naive" in v]
    assert "beyond the noise" not in line
    assert "inside the noise once the table's other differences are counted" in line
    assert "*" not in line.split(":", 1)[1]
