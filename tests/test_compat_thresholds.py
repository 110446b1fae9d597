"""Threshold fitting: recovers planted thresholds, deterministic, clear failures, selections."""

import numpy as np
import pytest

from elicit_jax.compat.selection import parse_selection, select_episodes
from elicit_jax.compat.threshold_fit import (
    FitConfig,
    evaluate_thresholds,
    fit_thresholds,
    incompatible_counts,
    operator_rejections,
)
from elicit_jax.compat.thresholds import (
    Thresholds,
    read_thresholds,
    read_thresholds_header,
    write_thresholds,
)
from elicit_jax.errors import ElicitError

LAM, ETA = 0.4, 0.05


def _planted(seed=0, n_comp=5, n_inc=5, length=80):
    """Synthetic scores whose separating region hugs the planted (λ, η) = (0.4, 0.05).

    Every demo: 30% novel pairs (ν in [0.052, 0.2]) with large ℓ in [0.5, 2], the rest
    familiar (ν < 0.046) with ℓ in [0, 0.38]. Incompatible demos also have 12 familiar pairs
    (15%) with ℓ in [0.42, 0.45] and ν in [0.044, 0.046]. So: η above 0.052 makes the novel
    pairs count (rejecting compatible demos), η below ~0.0447 misses the bad pairs; λ above
    ~0.44 misses them, λ below ~0.35 rejects compatible demos (> 5% of their pairs).
    """
    rng = np.random.default_rng(seed)
    ell, nu, ep, labels = [], [], [], {}
    for e in range(n_comp + n_inc):
        comp = e < n_comp
        novel = np.arange(length) < int(0.3 * length)
        err = np.where(novel, rng.uniform(0.5, 2.0, length), rng.uniform(0.0, 0.38, length))
        n = np.where(novel, rng.uniform(0.052, 0.2, length), rng.uniform(0.0, 0.046, length))
        if not comp:
            bad = np.arange(length) >= length - 12
            err[bad] = rng.uniform(0.42, 0.45, 12)
            n[bad] = rng.uniform(0.044, 0.046, 12)
        perm = rng.permutation(length)
        ell.append(err[perm]), nu.append(n[perm]), ep.append(np.full(length, 100 + e))
        labels[100 + e] = comp
    return np.concatenate(ell), np.concatenate(nu), np.concatenate(ep), labels


def test_incompatible_counts_by_hand():
    # one episode, pairs (l, nu): (0.5, 0.01) (0.2, 0.01) (0.9, 0.3)
    ell = np.array([0.5, 0.2, 0.9])
    nu = np.array([0.01, 0.01, 0.3])
    lams, etas = np.array([0.1, 0.6]), np.array([0.05, 0.5])
    c = incompatible_counts(ell, nu, np.zeros(3, int), 1, lams, etas)
    # lam 0.1, eta 0.05: pairs with l >= 0.1 and nu < 0.05 -> first two -> 2
    # lam 0.1, eta 0.5: all three -> 3; lam 0.6, eta 0.05: none -> 0; lam 0.6, eta 0.5: (0.9) -> 1
    np.testing.assert_array_equal(c[0], [[2, 3], [0, 1]])


def test_recovers_planted_thresholds():
    ell, nu, ep, labels = _planted()
    fit = fit_thresholds(ell, nu, ep, labels, FitConfig(grid_size=64))
    assert fit.balanced_accuracy == 1.0
    assert 0.35 <= fit.thresholds.lam <= 0.45
    assert 0.044 <= fit.thresholds.eta <= 0.052
    assert fit.loo_accuracy == 1.0 and fit.n_loo == 10
    assert fit.episodes["rejected"].tolist() == [False] * 5 + [True] * 5
    # the reported thresholds really give that accuracy when re-evaluated
    ba, _ = evaluate_thresholds(ell, nu, ep, labels, fit.thresholds)
    assert ba == 1.0


def test_fit_is_deterministic_and_order_invariant():
    ell, nu, ep, labels = _planted(seed=3)
    a = fit_thresholds(ell, nu, ep, labels)
    perm = np.random.default_rng(0).permutation(len(ell))
    b = fit_thresholds(ell[perm], nu[perm], ep[perm], labels)
    assert (a.thresholds, a.margin_steps) == (b.thresholds, b.margin_steps)


def test_single_demo_sets_have_no_loo():
    ell, nu, ep, labels = _planted(n_comp=1, n_inc=1)
    fit = fit_thresholds(ell, nu, ep, labels)
    assert fit.loo_accuracy is None and fit.n_loo == 0
    assert fit.balanced_accuracy == 1.0


def test_empty_and_degenerate_sets_fail_clearly():
    ell, nu, ep, labels = _planted()
    with pytest.raises(ElicitError, match="compatible set holds no"):
        fit_thresholds(ell, nu, ep, {k: False for k in labels})
    with pytest.raises(ElicitError, match="incompatible set holds no"):
        fit_thresholds(ell, nu, ep, {k: True for k in labels})
    # two copies of the same demo, one labelled each way: nothing can separate them
    same_ell = np.concatenate([ell[:80], ell[:80]])
    same_nu = np.concatenate([nu[:80], nu[:80]])
    same_ep = np.repeat([1, 2], 80)
    with pytest.raises(ElicitError, match="better than chance"):
        fit_thresholds(same_ell, same_nu, same_ep, {1: True, 2: False})


def test_operator_rejections_by_hand():
    # episode 0 (alice): 20 pairs, 2 incompatible (10% > 5%) -> rejected
    # episode 1 (bob): 20 pairs, 1 incompatible (5% = 5%) -> accepted
    ell = np.zeros(40)
    nu = np.zeros(40)
    ell[[0, 1, 20]] = 1.0
    ep = np.repeat([0, 1], 20)
    op = np.repeat(["alice", "bob"], 20)
    r = operator_rejections(ell, nu, ep, op, Thresholds(0.4, 0.05, "given"))
    assert r["alice"] == {
        "pairs": 20,
        "incompatible_pairs": 2,
        "episodes": 1,
        "rejected_episodes": 1,
    }
    assert r["bob"] == {"pairs": 20, "incompatible_pairs": 1, "episodes": 1, "rejected_episodes": 0}


def test_selections():
    cols = {
        "episode": np.array([0, 0, 1, 1, 2, 2]),
        "operator": np.array(["base", "base", "op", "op", "op", "op"], dtype=object),
        "success": np.array([True, True, True, False, False, False]),
    }
    assert select_episodes(parse_selection("operator:op"), cols).tolist() == [1, 2]
    assert select_episodes(parse_selection("episodes:2,0"), cols).tolist() == [0, 2]
    # label: every pair of the episode must match -> only episode 0 is all-true
    assert select_episodes(parse_selection("label:success=true"), cols).tolist() == [0]
    for bad in ("op:x", "operator:", "label:success", "episodes:a"):
        with pytest.raises(ElicitError, match="bad selection"):
            parse_selection(bad)
    with pytest.raises(ElicitError, match="matches no episode"):
        select_episodes(parse_selection("operator:carol"), cols)
    with pytest.raises(ElicitError, match="no episode"):
        select_episodes(parse_selection("episodes:7"), cols)
    # missing ids as ranges, not a list of every id
    want = r"no episode\(s\) 3-99,120 in the scores \(they hold 0-2\)"
    with pytest.raises(ElicitError, match=want):
        select_episodes(parse_selection("episodes:1-99,120"), cols)
    with pytest.raises(ElicitError, match="no column 'grade'"):
        select_episodes(parse_selection("label:grade=A"), cols)


def test_thresholds_artifact_round_trip(tmp_path):
    scores = tmp_path / "scores.parquet"
    scores.write_bytes(b"stand-in scores content")
    out = tmp_path / "t.json"
    given = Thresholds(0.3, 0.07, "given", policy="ab" * 32)
    inputs = {"scores": scores}
    write_thresholds(out, given, method="manual", inputs=inputs, config={}, report={})
    read = read_thresholds(out)
    assert (read.pair, read.file, read.policy, read.action_scale) == (
        (0.3, 0.07),
        out,
        "ab" * 32,
        "none",
    )
    header = read_thresholds_header(out)
    assert header["kind"] == "thresholds"
    assert len(header["inputs"]["scores"]["sha256"]) == 64
    bad = tmp_path / "bad.json"
    bad.write_text('{"kind": "demos"}')
    with pytest.raises(ElicitError, match="expected thresholds"):
        read_thresholds(bad)


# --- one carrier: no raw (λ, η) parameters outside the Thresholds module and the kernels ----

RAW_NAMES = {"lambda_", "lam", "eta", "et", "lmbda"}
RAW_ALLOWED = {
    "elicit_jax/compat/thresholds.py": "the Thresholds type, its validation and its JSON",
    "elicit_jax/compat/threshold_source.py": "command-line flags and presets into Thresholds",
    "elicit_jax/compat/measures.py": "the kernels: is_incompatible, compatibility, score_pair",
    "elicit_jax/compat/scorer.py": "the compiled kernel's inputs (ScoreInputs)",
    "elicit_jax/pipeline/report_rows.py": "field names are keys of committed report-data.json",
}


def raw_threshold_parameters(source: str) -> list[str]:
    """Function parameters and class fields of one module that carry λ or η as raw floats:
    named like λ/η, or a ``thresholds`` annotated as a tuple of floats."""
    import ast

    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            a = node.args
            for arg in (*a.posonlyargs, *a.args, *a.kwonlyargs):
                shape = ast.unparse(arg.annotation) if arg.annotation is not None else ""
                if arg.arg in RAW_NAMES or ("threshold" in arg.arg and "tuple[float" in shape):
                    found.append(f"{node.name}({arg.arg})")
        if isinstance(node, ast.ClassDef):
            for st in node.body:
                if isinstance(st, ast.AnnAssign) and isinstance(st.target, ast.Name):
                    shape = ast.unparse(st.annotation)
                    name = st.target.id
                    if name in RAW_NAMES or ("threshold" in name and "tuple[float" in shape):
                        found.append(f"{node.name}.{name}")
    return found


def test_no_raw_lambda_eta_parameters_outside_the_thresholds_module_and_the_kernels():
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    offenders = {}
    for path in sorted((root / "elicit_jax").rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if rel not in RAW_ALLOWED:
            found = raw_threshold_parameters(path.read_text())
            if found:
                offenders[rel] = found
    assert offenders == {}
    for rel in RAW_ALLOWED:
        assert (root / rel).exists(), rel


def test_the_raw_parameter_search_catches_planted_cases():
    planted = (
        "def filter_demos(scores, lambda_: float, eta: float): ...\n"
        "def write(out, thresholds: tuple[float, float]): ...\n"
        "class FilterConfig:\n    lam: float = 0.4\n    level: str = 'pair'\n"
    )
    assert raw_threshold_parameters(planted) == [
        "filter_demos(lambda_)",
        "filter_demos(eta)",
        "write(thresholds)",
        "FilterConfig.lam",
    ]
    assert raw_threshold_parameters("def f(t: Thresholds, level: str): ...\n") == []
