"""The valley rule: λ inside the fitted margin at the sparsest point of the new data's
familiar pairs; novel pairs do not count; a degenerate margin keeps the fitted λ."""

from __future__ import annotations

import numpy as np
import pytest

from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.compat.valley import log_density, valley_lambda


def test_lambda_moves_to_the_gap_between_two_clusters_of_familiar_pairs():
    rng = np.random.default_rng(0)
    # familiar pairs: log10 ℓ around -0.40 and around -0.10, nothing near -0.25
    logs = np.concatenate([rng.normal(-0.40, 0.03, 400), rng.normal(-0.10, 0.03, 400)])
    ell = 10.0**logs
    nu = np.full(ell.size, 0.01)
    # novel pairs (ν >= η) fill the gap; the rule must ignore them
    ell = np.concatenate([ell, np.full(300, 10.0**-0.25)])
    nu = np.concatenate([nu, np.full(300, 0.5)])
    lam, rep = valley_lambda(
        ell, nu, Thresholds(10**-0.12, 0.1, "fit"), low=10**-0.45, high=10**-0.05
    )
    assert np.log10(lam) == pytest.approx(-0.25, abs=0.03)
    assert rep["familiar_pairs"] == 800 and rep["density_ratio_chosen_to_fitted"] < 0.05
    # between the two λ: the upper cluster's lower tail (its centre is above the fitted λ)
    assert 0.0 < rep["familiar_share_between"] < 0.5


def test_degenerate_margin_or_no_familiar_pairs_keep_the_fitted_lambda():
    ell = np.array([0.1, 0.2, 0.3])
    lam, rep = valley_lambda(ell, np.zeros(3), Thresholds(0.2, 0.1, "fit"), 0.2, 0.2)
    assert lam == 0.2 and "single value" in rep["note"]
    lam, rep = valley_lambda(ell, np.ones(3), Thresholds(0.2, 0.1, "fit"), 0.1, 0.3)
    assert lam == 0.2 and "too few familiar" in rep["note"]


def test_density_by_hand():
    # one sample: density at distance d is exp(-d² / 2h²) relative to its peak
    x = np.array([0.0, 1.0])  # sd 0.7071, IQR 0.5 -> spread min(0.7071, 0.3731) = 0.3731
    h = 0.9 * 0.5 / 1.34 * 2 ** (-0.2)
    got = log_density(x, np.array([0.0, 0.5]))
    want = [np.log(1 + np.exp(-0.5 / h**2)), np.log(2 * np.exp(-0.125 / h**2))]
    np.testing.assert_allclose(got, want, rtol=1e-10)
