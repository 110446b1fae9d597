"""The incompatible test at its boundary, candidate thresholds, trust in a fit, and one
validation of (λ, η) in every command."""

import json

import jax.numpy as jnp
import numpy as np
import pytest
from typer.testing import CliRunner

from elicit_jax.artifact import make_header, write_parquet
from elicit_jax.cli import app
from elicit_jax.compat.filtering import FilterConfig, drop_mask
from elicit_jax.compat.fit import FitJob, fit_scores_file
from elicit_jax.compat.measures import ScoreConfig, score_pair
from elicit_jax.compat.threshold_fit import (
    evaluate_thresholds,
    fit_thresholds,
    incompatible_counts,
    operator_rejections,
)
from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.errors import ElicitError

# --- the tie ℓ = λ: the original code and the paper's "exceeds" do not flag it ------------


def test_a_pair_at_exactly_lambda_is_not_incompatible_anywhere():
    lam, eta = 0.5, 0.05
    # two members [0, 0] and [0, 0]; action [1, 0]: ℓ = mean([1, 0]) = 0.5 = λ; ν = 0
    s = score_pair(
        jnp.zeros((2, 2)),
        jnp.array([1.0, 0.0]),
        jnp.float32(lam),
        jnp.float32(eta),
        ScoreConfig.from_preset("square-nut"),
    )
    assert float(s.likelihood) == lam and float(s.novelty) == 0.0
    assert float(s.compatibility) == 0.0  # M bottoms out at the tie ...
    assert not bool(s.incompatible)  # ... but ℓ does not exceed λ
    # just above the tie it is flagged
    s2 = score_pair(
        jnp.zeros((2, 2)),
        jnp.array([1.0, 0.0]),
        jnp.float32(0.49),
        jnp.float32(eta),
        ScoreConfig.from_preset("square-nut"),
    )
    assert bool(s2.incompatible)
    # every NumPy path agrees: 20 pairs of one episode, 2 of them exactly at λ
    ell = np.zeros(20, np.float32)
    ell[:2] = lam
    nu = np.zeros(20, np.float32)
    ep = np.zeros(20, np.int64)
    counts = incompatible_counts(ell, nu, ep, 1, np.array([lam]), np.array([eta]))
    assert counts[0, 0, 0] == 0
    _, dec = evaluate_thresholds(
        np.r_[ell, ell * 0],
        np.r_[nu, nu],
        np.r_[ep, ep + 1],
        {0: False, 1: True},
        Thresholds(lam, eta, "given"),
    )
    assert dec["fraction_incompatible"].tolist() == [0.0, 0.0]
    assert (
        operator_rejections(ell, nu, ep, np.full(20, "op"), Thresholds(lam, eta, "given"))["op"][
            "incompatible_pairs"
        ]
        == 0
    )
    drop, _ = drop_mask(
        {"episode": ep, "likelihood": ell, "novelty": nu, "incompatible": np.zeros(20, bool)},
        FilterConfig(thresholds=Thresholds(lam, eta, "given")),
    )
    assert not drop.any()


# --- candidate thresholds sit between observed values ---------------------------------------


def _paused(seed=0):
    """Scores with heavy ties: operators that pause repeat identical pairs."""
    rng = np.random.default_rng(seed)
    ell, nu, ep, labels = [], [], [], {}
    for e in range(6):
        comp = e < 3
        base = rng.choice(np.float32([0.01, 0.02, 0.05, 0.1]), size=60)
        if not comp:
            base[:15] = np.float32(0.3)  # a pause: 15 identical high-error pairs
        ell.append(base.astype(np.float32))
        nu.append(rng.choice(np.float32([0.001, 0.002, 0.01]), size=60).astype(np.float32))
        ep.append(np.full(60, e))
        labels[e] = comp
    return np.concatenate(ell), np.concatenate(nu), np.concatenate(ep), labels


def test_candidates_lie_strictly_between_observed_values():
    from elicit_jax.compat.threshold_fit import candidates

    ell, nu, ep, labels = _paused()
    for values, upper in ((ell, False), (nu, True)):
        cand = candidates(values, 64, upper=upper)
        assert not np.isin(cand.astype(np.float32), values).any()
        u = np.unique(values)
        # every candidate lies strictly inside a gap between neighbouring observed values,
        # or just above the largest
        k = np.searchsorted(u, cand.astype(np.float32))
        assert ((k == len(u)) | (u[np.minimum(k, len(u) - 1)] > cand)).all()
        assert (cand > u[np.maximum(k - 1, 0)]).all()
    fit = fit_thresholds(ell, nu, ep, labels)
    assert np.float32(fit.thresholds.lam) not in set(ell.tolist())
    assert np.float32(fit.thresholds.eta) not in set(nu.tolist())
    # the fitted λ separates: the paused pairs (0.3) exceed it, the others (<= 0.1) do not
    assert 0.1 < fit.thresholds.lam < 0.3 and fit.balanced_accuracy == 1.0


# --- trust -------------------------------------------------------------------------------------


def _scores_file(path, ell, nu, ep, ops):
    import pyarrow as pa

    n = len(ell)
    steps = np.concatenate([np.arange((ep == e).sum()) for e in np.unique(ep)])
    table = pa.table(
        {
            "episode": pa.array(np.asarray(ep, np.int64)),
            "operator": pa.array([str(o) for o in ops]),
            "step": pa.array(steps.astype(np.int32)),
            "likelihood": pa.array(np.asarray(ell, np.float32)),
            "novelty": pa.array(np.asarray(nu, np.float32)),
            "compatibility": pa.array(np.ones(n, np.float32)),
            "incompatible": pa.array(np.zeros(n, bool)),
            "source_episode": pa.array([f"demo_{e}" for e in ep]),
        }
    )
    write_parquet(path, table, make_header("scores", 1, thresholds={"lambda": 0.4, "eta": 0.05}))
    return path


def _separable(rng, n_base=8, n_bad=4, length=60):
    """Base demos: small errors; the bad operator: 20% of pairs with large errors."""
    ell, ep, ops = [], [], []
    for e in range(n_base + n_bad):
        err = rng.uniform(0.0, 0.1, length)
        if e >= n_base:
            err[:12] = rng.uniform(0.5, 0.9, 12)
        ell.append(err)
        ep.append(np.full(length, e))
        ops.append(np.full(length, "base" if e < n_base else "bad"))
    ell, ep, ops = map(np.concatenate, (ell, ep, ops))
    return ell, rng.uniform(0.0, 0.01, len(ell)), ep, ops


def test_a_clean_fit_is_trustworthy(tmp_path):
    ell, nu, ep, ops = _separable(np.random.default_rng(0))
    f = _scores_file(tmp_path / "s.parquet", ell, nu, ep, ops)
    job = FitJob(compatible="episodes:0-3", incompatible="operator:bad")
    h = fit_scores_file(f, tmp_path / "t.json", job)
    trust = h["report"]["trust"]
    assert trust == {
        "trustworthy": True,
        "meaningless": False,
        "problems": [],
        "severe": [],
        "forced": False,
        # hand-made scores record no policy, so nothing can be checked against its training
        "unchecked": ["the training-data checks (the scores file records no policy checkpoint)"],
    }
    assert h["report"]["contrast"][0]["source_episode"] == "demo_0"


def test_one_operator_split_in_two_is_refused_then_forced(tmp_path):
    """Two halves of one operator's demos: any fit is noise. The issue's case."""
    rng = np.random.default_rng(1)
    ell = rng.gamma(1.0, 0.05, 20 * 60)
    nu = rng.uniform(0.0, 0.02, len(ell))
    ep = np.repeat(np.arange(20), 60)
    ops = np.full(len(ell), "alice")
    f = _scores_file(tmp_path / "s.parquet", ell, nu, ep, ops)
    job = FitJob(compatible="episodes:0-9", incompatible="episodes:10-19")
    with pytest.raises(ElicitError, match=r"meaningless.*--force"):
        fit_scores_file(f, tmp_path / "t.json", job)
    assert not (tmp_path / "t.json").exists()
    forced = FitJob(compatible="episodes:0-9", incompatible="episodes:10-19", force=True)
    h = fit_scores_file(f, tmp_path / "t.json", forced)
    trust = json.loads((tmp_path / "t.json").read_text())["report"]["trust"]
    assert trust["trustworthy"] is False and trust["meaningless"] and trust["forced"]
    assert h["report"]["trust"]["severe"]


def test_thresholds_that_reject_the_base_operator_are_refused(tmp_path):
    """Held-out base demos vs an operator whose demos look alike; the thresholds then reject
    most of the base operator's own (training) demos."""
    rng = np.random.default_rng(2)
    length = 60
    ell, ep, ops = [], [], []
    for e in range(14):
        err = rng.uniform(0.0, 0.1, length)
        if e in (0, 1):  # the two held-out base demos happen to be very clean
            err = rng.uniform(0.0, 0.02, length)
        ell.append(err)
        ep.append(np.full(length, e))
        ops.append(np.full(length, "base" if e < 10 else "lookalike"))
    ell, ep, ops = map(np.concatenate, (ell, ep, ops))
    nu = rng.uniform(0.0, 0.01, len(ell))
    f = _scores_file(tmp_path / "s.parquet", ell, nu, ep, ops)
    job = FitJob(compatible="episodes:0,1", incompatible="operator:lookalike")
    with pytest.raises(ElicitError, match=r"reject \d+ of 10 demonstrations of operator 'base'"):
        fit_scores_file(f, tmp_path / "t.json", job)


def test_problems_short_of_meaningless_are_written_and_flagged(tmp_path):
    # one demo per set, few pairs: written, but marked not trustworthy
    ell, nu, ep, ops = _separable(np.random.default_rng(3), n_base=1, n_bad=1, length=30)
    f = _scores_file(tmp_path / "s.parquet", ell, nu, ep, ops)
    h = fit_scores_file(f, tmp_path / "t.json", FitJob("operator:base", "operator:bad"))
    trust = h["report"]["trust"]
    assert trust["trustworthy"] is False and not trust["meaningless"]
    text = " ".join(trust["problems"])
    assert "no held-out" in text and "only 30 state-action pairs" in text


# --- CLI: one validation of thresholds, options given twice, hand-set thresholds ---------


@pytest.fixture(scope="module")
def scores(tmp_path_factory):
    d = tmp_path_factory.mktemp("trust-cli")
    ell, nu, ep, ops = _separable(np.random.default_rng(0))
    return _scores_file(d / "s.parquet", ell, nu, ep, ops)


def _run(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.mark.parametrize("lam,eta", [("-1", "0.05"), ("0.4", "0"), ("nan", "0.05")])
def test_every_command_validates_thresholds_the_same_way(scores, tmp_path, lam, eta):
    name = "lambda" if lam != "0.4" else "eta"
    runs = {
        "score": ["score", "--policy", tmp_path, "--demos", tmp_path / "d.parquet"],
        "filter": ["filter", "--scores", scores, "--demos", tmp_path / "d.parquet"],
        "map": ["map", "--scores", scores],
        "fit-thresholds": ["fit-thresholds", "--scores", scores],
    }
    for cmd, args in runs.items():
        out = tmp_path / f"{cmd}.{'png' if cmd == 'map' else 'json'}"
        r = _run(*args, "-o", out, "--lambda", lam, "--eta", eta)
        assert isinstance(r.exception, ElicitError), (cmd, r.output)
        assert f"{name} must be a finite number > 0" in str(r.exception), cmd
        assert not out.exists()


def test_an_option_given_twice_is_refused(scores, tmp_path):
    r = _run(
        *("fit-thresholds", "--scores", scores, "--scores", scores, "--lambda", "0.4"),
        *("--eta", "0.05", "-o", tmp_path / "t.json"),
    )
    assert r.exit_code == 2 and "'--scores' of 'fit-thresholds'" in r.output
    assert "given 2 times" in r.output
    assert not (tmp_path / "t.json").exists()
    r = _run("score", "-o", "a", "--out=b")
    assert r.exit_code == 2 and "given 2 times" in r.output


def test_hand_set_thresholds_need_no_contrast_sets(scores, tmp_path):
    r = _run(
        *("fit-thresholds", "--scores", scores, "--lambda", "0.4", "--eta", "0.05"),
        *("-o", tmp_path / "t.json"),
    )
    assert r.exit_code == 0, r.output
    t = json.loads((tmp_path / "t.json").read_text())
    assert (t["lambda"], t["eta"], t["method"]) == (0.4, 0.05, "manual")
    assert t["report"]["per_operator"]["bad"]["rejected_episodes"] == 4
    r = _run("fit-thresholds", "--scores", scores, "-o", tmp_path / "u.json")
    assert "fitting needs contrast sets" in str(r.exception)


def test_untrustworthy_thresholds_warn_where_they_are_used(scores, tmp_path):
    r = _run(
        *("fit-thresholds", "--scores", scores, "--compatible", "episodes:0"),
        *("--incompatible", "episodes:8", "-o", tmp_path / "t.json"),
    )
    assert r.exit_code == 0, r.output
    assert "NOT TRUSTWORTHY" in r.output
    r = _run(
        "map", "--scores", scores, "--thresholds", tmp_path / "t.json", "-o", tmp_path / "m.png"
    )
    assert r.exit_code == 0
    assert "judged when fitted: NOT TRUSTWORTHY: one demonstration per set" in r.output


def test_help_lists_commands_in_workflow_order():
    r = _run("--help")
    text = r.output
    order = ["import", "demos", "train", "score", "fit-thresholds", "filter", "export"]
    pos = [text.index(f"│ {name} ") for name in order if f"│ {name} " in text]
    assert pos == sorted(pos) and len(pos) >= 6
    assert text.index("1. Bring demonstrations") < text.index("3. Compatibility")


def test_the_pipeline_report_carries_the_trust_verdict():
    from elicit_jax.pipeline.tables import ReportData, ThresholdRow, threshold_table

    bad = {"trustworthy": False, "meaningless": False, "problems": ["no margin: …"]}
    rows = [
        ThresholdRow("t", "mlp", 0.4, 0.05, "c", "i", {"trust": bad}),
        ThresholdRow("t", "mdn", 0.4, 0.05, "c", "i", {"trust": {"trustworthy": True}}),
    ]
    data = ReportData("p", "cpu", "", "", "", (), thresholds=tuple(rows))
    header, table = threshold_table(data)
    col = header.index("trust")
    assert table[0][col] == "NOT TRUSTWORTHY: no margin: …" and table[1][col] == "ok"
