"""KSG estimator: exact neighbour counts on a hand-built set, known MI of correlated
Gaussians; DemInf ranks conflicting demonstrations lowest."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import digamma

from elicit_jax.curation.deminf import DemInfConfig, deminf_scores, standardise
from elicit_jax.curation.ksg import ksg_counts, ksg_mutual_information, ksg_terms
from elicit_jax.data.demos import from_episodes
from elicit_jax.errors import ElicitError

# Five points; joint distance max(|dx|, |dy|). Worked by hand (see the comments in the test).
X = np.array([0.0, 1.0, 3.0, 6.0, 10.0])
Y = np.array([0.0, 3.0, 1.0, 4.0, 2.0])


def test_neighbour_counts_by_hand():
    # joint distances: d01=3 d02=3 d03=6 d04=10 d12=2 d13=5 d14=9 d23=3 d24=7 d34=4
    eps, n_x, n_y = ksg_counts(X, Y, ks=(1, 2), chunk=2)  # chunk 2: padding exercised
    assert eps[:, 0].tolist() == [3, 2, 2, 3, 4]  # nearest joint neighbour
    assert eps[:, 1].tolist() == [3, 3, 3, 4, 7]  # second nearest
    # other points strictly closer than eps in x alone, and in y alone
    assert n_x[:, 0].tolist() == [1, 1, 0, 0, 0]
    assert n_y[:, 0].tolist() == [2, 2, 2, 2, 4]
    assert n_x[:, 1].tolist() == [1, 2, 1, 1, 1]
    assert n_y[:, 1].tolist() == [2, 3, 3, 3, 4]
    terms = ksg_terms(X, Y, ks=(1,))
    want = digamma(1) + digamma(5) - digamma(np.array([2, 2, 1, 1, 1]) + 0.0)
    want -= digamma(np.array([3, 3, 3, 3, 5]) + 0.0)
    np.testing.assert_allclose(terms[:, 0], want, rtol=1e-12)


@pytest.mark.parametrize("rho", [0.0, 0.6, 0.9])
def test_mutual_information_of_correlated_gaussians(rho):
    rng = np.random.default_rng(1)
    z = rng.multivariate_normal([0, 0], [[1, rho], [rho, 1]], size=1500)
    truth = -0.5 * np.log(1 - rho**2)
    assert ksg_mutual_information(z[:, 0], z[:, 1], k=3) == pytest.approx(truth, abs=0.05)


def test_multivariate_marginals_use_euclidean_distance_and_ignore_independent_dims():
    rng = np.random.default_rng(2)
    rho = 0.8
    z = rng.multivariate_normal([0, 0], [[1, rho], [rho, 1]], size=1500)
    x = np.stack([z[:, 0], rng.normal(size=1500)], axis=1)  # an independent extra dim in x
    truth = -0.5 * np.log(1 - rho**2)
    assert ksg_terms(x, z[:, 1], ks=(5, 6, 7)).mean() == pytest.approx(truth, abs=0.08)


def test_bad_input_is_a_one_line_error():
    with pytest.raises(ElicitError, match="more than 3 samples"):
        ksg_counts(X[:3], Y[:3], ks=(3,))
    with pytest.raises(ElicitError, match="non-finite"):
        ksg_counts(np.array([0, 1, np.nan, 3, 4.0]), Y, ks=(1,))


def _episodes(rng, n, sign, t=30):
    eps = []
    for _ in range(n):
        s = rng.uniform(-1, 1, size=(t, 3)).astype(np.float32)
        a = np.tanh(sign * s[:, :2] * 1.5) + 0.02 * rng.normal(size=(t, 2))
        eps.append({"obs": s, "action": np.clip(a, -1, 1).astype(np.float32)})
    return eps


def test_deminf_scores_conflicting_demos_lowest():
    rng = np.random.default_rng(3)
    base = from_episodes(_episodes(rng, 12, +1.0), operators="base")
    good, bad = _episodes(rng, 6, +1.0), _episodes(rng, 4, -1.0)
    order = [0, 6, 1, 7, 2, 8, 3, 9, 4, 5]  # interleave: bad demos at positions 1, 3, 5, 7
    eps = [(good + bad)[i] for i in order]
    new = from_episodes(eps, operators="new", episode_ids=list(range(100, 110)))
    scores = deminf_scores(new, base, DemInfConfig(ks=(3, 4)))
    assert scores.episode.tolist() == list(range(100, 110))
    assert scores.threshold is None and scores.trusted
    lowest = sorted(np.argsort(scores.score)[:4].tolist())
    assert lowest == [1, 3, 5, 7]
    assert scores.report["n_pairs"] == 22 * 30
    assert scores.report["base_demo_scores"]["mean"] > scores.score[[1, 3, 5, 7]].max()


def test_standardise_leaves_constant_columns_at_zero():
    x = np.array([[1.0, 5.0], [3.0, 5.0]])
    np.testing.assert_allclose(standardise(x), [[-1.0, 0.0], [1.0, 0.0]])
