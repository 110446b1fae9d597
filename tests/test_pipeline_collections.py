"""A study over several collections: the [collections] table, its stage graph, the pooled
statistics (hand-computed), and the across-collections table (no training here)."""

from __future__ import annotations

import dataclasses
import math
import tomllib

import pytest

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.across import across_note, across_tables, paired_by_collection
from elicit_jax.pipeline.evidence import selection_meta
from elicit_jax.pipeline.plan import COLLECTION_STRIDE, build_graph
from elicit_jax.pipeline.spec import load_spec, parse_spec
from elicit_jax.pipeline.tables import ReportData, ResultRow, results_tables
from elicit_jax.stats import collections_interval, format_collections_diff

SPEC = """
[pipeline]
name = "mini"
seeds = [0, 1]
methods = ["base", "naive", "filtered", "random", "longest"]
[[task]]
name = "reach-pillar"
operators = ["a", "b"]
incompatible_operator = "c"
[sensitivity]
points = 2
seeds = [7]
eval_seed = 1
"""


def _spec(extra: str = "", profile: str | None = None):
    text = SPEC + extra
    return parse_spec(tomllib.loads(text), source="mini.toml", text=text, profile=profile)


# --- statistics, by hand ---------------------------------------------------------------------


def test_equal_differences_give_a_point_interval():
    d = collections_interval([[0.2, 0.2, 0.2], [0.2, 0.2]])
    assert (d.mean, d.low, d.high) == pytest.approx((0.2, 0.2, 0.2))
    assert d.n_pairs == 5 and d.agreeing == 2 and d.no_spread and math.isnan(d.p)


def test_the_interval_is_student_t_over_the_collection_means_by_hand():
    # means 0.1, 0.3 (seeds averaged first): mean 0.2, sd 0.1414, se 0.1, t(0.975, 1) 12.706
    d = collections_interval([[0.1] * 5, [0.3] * 5])
    assert d.mean == pytest.approx(0.2)
    assert (d.low, d.high) == pytest.approx((0.2 - 1.27062, 0.2 + 1.27062), abs=1e-5)
    assert d.per_collection == pytest.approx((0.1, 0.3)) and d.agreeing == 2
    assert not d.excludes_zero and d.p == pytest.approx(1 - 2 * math.atan(2) / math.pi)
    # three collections 0.1, 0.2, 0.3 (uneven seed counts: each collection weighs the same)
    e = collections_interval([[0.1], [0.2, 0.2, 0.2, 0.2], [0.25, 0.35]])
    half = 4.302653 * 0.1 / math.sqrt(3)
    assert (e.mean, e.low, e.high) == pytest.approx((0.2, 0.2 - half, 0.2 + half), abs=1e-6)
    assert format_collections_diff(e, adjusted=0.5) == (
        "+20.0 [-4.8, +44.8] (Holm p 0.500); 3/3 collections agree in sign (sign test p 0.250)"
    )


def test_a_pooled_difference_without_spread_is_not_called_beyond_the_noise():
    d = collections_interval([[0.1] * 3, [0.1] * 3])  # every pair differs by exactly 10 points
    assert d.no_spread and not d.excludes_zero
    assert format_collections_diff(d, adjusted=math.nan) == (
        "+10.0 [+10.0, +10.0] (no spread, not a test); 2/2 collections agree in sign "
        "(sign test p 0.500)"
    )
    same = collections_interval([[0.0] * 3, [0.0] * 3])  # identical policies
    assert format_collections_diff(same, adjusted=math.nan) == (
        "+0.0 [+0.0, +0.0]; 2/2 collections agree in sign"
    )


def test_one_collection_gives_no_interval():
    d = collections_interval([[0.0, 1.0]])  # the collection is the unit: one is no sample
    assert d.mean == pytest.approx(0.5) and math.isnan(d.low) and math.isnan(d.high)
    assert not d.excludes_zero and math.isnan(d.p)


def test_a_mark_needs_the_adjusted_p_value():
    d = collections_interval([[0.10, 0.12], [0.2, 0.22], [0.15, 0.17]])
    assert d.excludes_zero and d.p < 0.05
    assert format_collections_diff(d).split(";")[0].endswith(" *")  # a lone comparison
    assert "*" not in format_collections_diff(d, adjusted=0.2)
    assert format_collections_diff(d, adjusted=0.01).split(";")[0].endswith(") *")


def test_sign_disagreement_and_determinism():
    d = collections_interval([[-0.1, -0.1], [0.3, 0.3], [0.1, 0.2]])
    assert d.mean == pytest.approx((-0.1 + 0.3 + 0.15) / 3)
    assert d.agreeing == 2  # the first collection is below 0, the pooled mean above
    assert d == collections_interval([[-0.1, -0.1], [0.3, 0.3], [0.1, 0.2]])
    assert d.low < d.mean < d.high and d.sign_p == pytest.approx(1.0)


@pytest.mark.parametrize(
    "diffs, message",
    [
        ([], "no collection"),
        ([[0.1], []], "collection 1: no paired training seed"),
        ([[0.1, float("nan")]], "collection 0: a paired difference is not finite"),
    ],
)
def test_bad_inputs_to_the_interval(diffs, message):
    with pytest.raises(ElicitError, match=message):
        collections_interval(diffs)


# --- the [collections] table ------------------------------------------------------------------


@pytest.mark.parametrize(
    "table, message",
    [
        ("[collections]\nseeds = [0, 1]\nwho = 1", r"\[collections\]: unknown key\(s\) who"),
        ("[collections]\nseeds = []", "seeds must be a non-empty list"),
        ("[collections]\nmethods = ['base']", "seeds must be a non-empty list"),
        ("[collections]\nseeds = [0, 1, 0]", r"seeds are listed twice: \[0, 1, 0\]"),
        ("[collections]\nseeds = [0, -1]", "non-negative integers"),
        ("[collections]\nseeds = [0, 1]\nmethods = []", "methods must not be empty"),
        ("[collections]\nseeds = [0, 1]\nmethods = ['base', 'cupid']", "cupid are not in"),
        ("[collections]\nseeds = [0, 1]\nmethods = ['naive']", "must include 'base'"),
        ("[profiles.cpu.collections]\nseeds = 3", "non-empty list"),
    ],
)
def test_bad_collections_tables_fail_with_one_line_naming_the_file(table, message):
    with pytest.raises(ElicitError, match=message) as err:
        _spec(table, profile="cpu")
    assert str(err.value).startswith("mini.toml: ") and "\n" not in str(err.value)


def test_profile_overrides_the_collections_table():
    table = "[collections]\nseeds = [0, 1]\n[profiles.cpu.collections]\nseeds = [0, 1, 2]\n"
    assert _spec(table, "paper").collections.seeds == (0, 1)
    cpu = _spec(table, "cpu").collections
    assert cpu.seeds == (0, 1, 2) and cpu.methods == _spec().methods  # default: every method
    assert _spec().collections is None


def test_collection_zero_keeps_the_study_graph_and_the_others_are_disjoint():
    plain = build_graph(_spec())
    multi = build_graph(
        _spec("[collections]\nseeds = [0, 2]\nmethods = ['base', 'naive', 'filtered']\n")
    )
    mine = {s.id: s for s in multi if "/c2/" not in s.id}
    assert set(mine) == {s.id for s in plain}
    for s in plain:
        if s.id != "report":
            assert (mine[s.id].output, dict(mine[s.id].config), dict(mine[s.id].inputs)) == (
                s.output,
                dict(s.config),
                dict(s.inputs),
            )
    c2 = [s for s in multi if "/c2/" in s.id]
    assert {s.id.split("/")[1] for s in c2} == {"c2"}
    assert all(s.config["collection"] == 2 and s.label.startswith("c2: ") for s in c2)
    for s in c2:  # every input of a later collection's stage is inside that collection
        assert all("/c2/" in dep for dep in s.inputs.values())
    seeds = {s.config["seed"]: s.id for s in multi if s.kind == "collect"}
    assert len(seeds) == 2 * 5  # base, holdout, incompatible, 2 × D_new per collection
    assert sorted(seeds)[5:] == [2 * COLLECTION_STRIDE + o for o in (0, 1, 2, 10, 11)]
    methods = {s.config["method"] for s in c2 if s.kind == "train"}
    assert methods == {"base", "naive", "filtered"}  # the first collection also runs the rest
    assert not any(s.kind == "lambda-point" for s in c2)  # the λ study: first collection only
    maps = [s.output for s in multi if s.kind == "map"]
    assert len({m.rsplit("/", 1)[-1] for m in maps}) == 2  # distinct names in a report folder
    assert set(multi["report"].inputs) >= {s.id for s in c2 if s.kind == "evaluate"}


def test_shipped_filtering_cpu_runs_three_collections():
    spec = load_spec("filtering", "cpu", ("round-nut",))
    assert spec.collections.seeds == (0, 1, 2)
    assert spec.collections.methods == (
        "base", "naive", "filtered", "filtered-episode", "random", "deminf-matched",
    )  # fmt: skip
    graph = build_graph(spec)
    for c in ("c1", "c2"):  # 16 trainings per extra collection: base + 3 operators × 5
        assert sum(s.kind == "train" and f"/{c}/" in s.id for s in graph) == 16
    assert load_spec("filtering", "paper").collections is None
    # D_new is scored under the fitted thresholds, the contrast sets before the fit
    score = graph["score/round-nut/mlp/mild"]
    assert score.inputs["thresholds"] == "fit-thresholds/round-nut/mlp"
    assert "thresholds" not in graph["score/round-nut/mlp/contrast"].inputs


def test_shipped_phenomenon_is_base_and_naive_on_five_collections():
    """The phenomenon on the pipeline engine: per task, Base and Naive per operator on 5
    collections × 3 training seeds, nothing else (no contrast sets, scores or filters)."""
    spec = load_spec("phenomenon", "paper")
    assert spec.methods == ("base", "naive") and spec.seeds == (0, 1, 2)
    assert spec.collections.seeds == (0, 1, 2, 3, 4)
    graph = build_graph(spec)
    kinds = sorted({s.kind for s in graph})
    assert kinds == ["collect", "evaluate", "report", "train"]
    per_task = 5 * (1 + 2)  # collections × (Base + Naive per operator)
    assert sum(s.kind == "train" for s in graph) == 4 * per_task
    train = graph["train/square-nut/mlp/naive/conflict-flip-pause"]
    assert (train.config["hidden"], train.config["ensemble_size"], train.config["epochs"]) == (
        [256, 256], 2, 150,
    )  # fmt: skip
    evaluate = graph["evaluate/square-nut/mlp/base"].config
    assert selection_meta(evaluate, 0) == {"selection": "heldout", "select_seed": 100}


def test_shipped_robosuite_phenomenon_evaluates_the_final_checkpoint_only():
    spec = load_spec("phenomenon-robosuite", "paper", ("robosuite-square",))
    graph = build_graph(spec)
    assert sum(s.kind == "train" for s in graph) == 5 * (1 + 2)
    evaluate = graph["evaluate/robosuite-square/mlp/naive-conflict-down"].config
    assert evaluate["checkpoints"] == ["final"]
    assert selection_meta(evaluate, 0) == {"selection": "reported"}


# --- the across-collections table -------------------------------------------------------------


def _row(collection, method, op, seed, success, states="s"):
    return ResultRow("t", "mlp", method, op, seed, success, 50.0, 4, "best", states,
                     collection=collection)  # fmt: skip


def _data(rows):
    return ReportData("p", "cpu", "", "run", "", tuple(rows))


def test_across_table_pools_collections_and_pairs_by_seed():
    rows = []
    for c, (base, naive) in enumerate([(0.5, 0.25), (0.5, 0.75)]):
        for s in (0, 1):
            rows += [_row(c, "base", None, s, base), _row(c, "naive", "op", s, naive)]
    data = _data(rows)
    ((title, (header, table)),) = across_tables(data)
    assert "across 2 collections [0, 1]" in title and "Student t interval over the 2" in title
    assert "Holm-adjusted over the 1 differences of this table" in title
    assert header[2:] == ["success % mean (std)", "− Naive", "− Base"]
    assert table[0][:3] == ["–", "Base", "50.0 (0.0)"]
    # Naive: 25, 25, 75, 75 → mean 50.0, std (ddof 1) 28.9; Naive − Base: −25 in collection 0,
    # +25 in collection 1: mean 0, se 25, t(0.975, 1) 12.706 → ±317.7; none agrees with 0
    assert table[1][:3] == ["op", "Naive", "50.0 (28.9)"]
    assert table[1][4] == (
        "+0.0 [-317.7, +317.7] (Holm p 1.000); 0/2 collections agree in sign (sign test p 1.000)"
    )
    # per-collection tables as before, titled with their collection
    titles = [t for t, _ in results_tables(data)]
    assert titles[0].startswith("collection 0: t — mlp") and titles[1].startswith("collection 1")
    assert "in 0 of 1 paired differences all 2 collections" in across_note(data)[1]
    assert across_tables(_data(r for r in rows if r.collection == 0)) == []


def test_the_m_filter_is_compared_with_the_random_drop_and_adjusted_with_the_table():
    rows = []
    for c, shift in enumerate((0.0, 0.02, 0.04)):
        for s in (0, 1, 2):
            wiggle = 0.01 * s
            rows += [
                _row(c, "base", None, s, 0.5),
                _row(c, "naive", "op", s, 0.2 + shift + wiggle),
                _row(c, "filtered", "op", s, 0.5 + 1.5 * shift),
                _row(c, "random", "op", s, 0.22 + shift + wiggle),
            ]
    ((title, (header, table)),) = across_tables(_data(rows))
    assert header[-1] == "− Random filter (same amount)"
    m_row = next(r for r in table if r[1] == "M-Filtered")
    random_row = next(r for r in table if r[1] == "Random filter")
    # M − Random per collection: 27, 28, 29 points → 28 ± 4.303 · 1 / √3 · 1 ... = [+25.5, +30.5]
    assert m_row[-1].startswith("+28.0 [+25.5, +30.5] (Holm p ") and random_row[-1] == ""
    assert m_row[-1].split(";")[0].endswith("*")
    # 6 differences: Naive − Base, M − Naive, M − Base, Random − Naive, Random − Base,
    # M − Random; Random − Naive has no spread (+2.0 in every collection): not a test
    assert "Holm-adjusted over the 5 differences of this table" in title
    assert "(no spread, not a test)" in random_row[3]


def test_pairs_on_different_initial_states_are_not_compared():
    a = [_row(0, "naive", "op", 0, 0.5, "x")]
    b = [_row(0, "base", None, 0, 0.25, "y")]
    assert paired_by_collection(a, b, [0]) is None
    b = [dataclasses.replace(b[0], init_states="x")]
    assert paired_by_collection(a, b, [0]) == [[0.25]]


_ORDER_SCRIPT = """
from tests.test_pipeline_collections import _data, _row
from elicit_jax.pipeline.across import across_tables
ops = ["same-style", "mild", "conflict-flip-pause", "op-d", "op-e"]
rows = [_row(c, "base", None, s, 0.5) for c in (0, 1) for s in (0, 1)]
rows += [_row(c, "naive", op, s, 0.25) for op in ops for c in (0, 1) for s in (0, 1)]
((_, (_, table)),) = across_tables(_data(rows))
print(",".join(r[0] for r in table[1:]))
"""


def test_across_table_lists_operators_in_the_study_order_under_any_hash_seed():
    """The table's rows follow the results (the definition's operator order), not a set's
    iteration order: string hashing is salted per process, and a report must rebuild byte for
    byte in another process."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    want = "same-style,mild,conflict-flip-pause,op-d,op-e"
    for seed in ("0", "1", "2", "3", "4", "5"):
        env = {**os.environ, "PYTHONHASHSEED": seed, "JAX_PLATFORMS": "cpu"}
        out = subprocess.run(
            [sys.executable, "-c", _ORDER_SCRIPT], cwd=root, env=env, capture_output=True,
            text=True, check=True,
        )  # fmt: skip
        assert out.stdout.strip() == want, f"PYTHONHASHSEED={seed}: {out.stdout.strip()}"
