"""An optional rule for λ inside the fitted margin: the sparsest point of the new data.

The fit (:mod:`~elicit_jax.compat.thresholds`) finds a range of λ — its margin — over which
every contrast demonstration gets the same decision, and takes a point in it. The contrast
sets cannot tell the λ values of that range apart; the unlabelled new data can. If λ cuts
through a dense cluster of the new data's familiar pairs (ν < η), a small change of λ flips
many pairs between kept and dropped, so the filter's outcome hangs on an arbitrary choice
inside a range the labels say nothing about. The **valley rule** therefore places λ, inside the
margin's λ range, where the familiar pairs of all D_new are sparsest: the minimum of a Gaussian
kernel density of their log ℓ (Silverman's bandwidth), over a log-spaced grid of the range. Ties
go to the candidate nearest the fitted λ. This is low-density separation, as in
semi-supervised learning; it never leaves the range the contrast sets allow.

It is an option (the pipeline method ``filtered-valley``); the fitted λ stays the default.

Example:
    >>> lam, report = valley_lambda(ell, nu, Thresholds(0.56, 0.11, "fit"), low=0.47, high=0.66)
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.errors import ElicitError


def log_density(x: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Gaussian kernel density of samples ``x (n,)`` at ``at (m,)``, Silverman's bandwidth
    (0.9 · min(sd, IQR / 1.34) · n^(−1/5)); unnormalised log values."""
    x = np.asarray(x, np.float64)
    spread = min(x.std(ddof=1), (np.quantile(x, 0.75) - np.quantile(x, 0.25)) / 1.34)
    h = 0.9 * max(spread, 1e-6) * x.size ** (-0.2)
    z = (np.asarray(at, np.float64)[:, None] - x[None, :]) / h
    m = (-0.5 * z * z).max(axis=1, keepdims=True)
    return (m + np.log(np.exp(-0.5 * z * z - m).sum(axis=1, keepdims=True)))[:, 0]


def valley_lambda(
    ell: np.ndarray,
    nu: np.ndarray,
    thresholds: Thresholds,
    low: float,
    high: float,
    grid: int = 201,
) -> tuple[float, dict[str, Any]]:
    """λ in ``[low, high]`` where the familiar pairs' log ℓ density is lowest.

    Args:
      ell: (N,) likelihood errors of the new data's pairs (all operators pooled).
      nu: (N,) their novelty.
      thresholds: the fitted (λ, η): λ is where the search starts from, η says which pairs
        are familiar (ν < η).
      low: lower end of the margin's λ range.
      high: upper end.
      grid: log-spaced candidates over the range.

    Returns:
      ``(λ, report)``; the report gives the density at the fitted and the chosen λ and the
      share of familiar pairs between them.
    """
    ell, nu = np.asarray(ell, np.float64), np.asarray(nu, np.float64)
    fitted, eta = thresholds.pair
    if not (0 < low <= fitted <= high):
        raise ElicitError(
            f"valley rule needs 0 < low <= fitted <= high, got {low}, {fitted}, {high}"
        )
    familiar = ell[(nu < eta) & (ell > 0)]
    report: dict[str, Any] = {
        "rule": "new-data-valley",
        "lambda_range": [low, high],
        "fitted_lambda": fitted,
        "familiar_pairs": int(familiar.size),
    }
    if high == low or familiar.size < 2:
        why = "the margin's λ range is a single value" if high == low else "too few familiar pairs"
        return fitted, {**report, "lambda": fitted, "note": f"{why}: kept the fitted λ"}
    cands = np.geomspace(low, high, grid)
    logs = np.log10(familiar)
    dens = log_density(logs, np.log10(cands))
    best = np.flatnonzero(dens <= dens.min() + 1e-12)
    lam = float(cands[best[np.argmin(np.abs(np.log(cands[best] / fitted)))]])
    at_fit = float(log_density(logs, np.log10([fitted]))[0])
    lo, hi = sorted((lam, fitted))
    between = float(((familiar >= lo) & (familiar < hi)).mean())
    return lam, {
        **report,
        "lambda": lam,
        "log_density_fitted": at_fit,
        "log_density_chosen": float(dens.min()),
        "density_ratio_chosen_to_fitted": math.exp(float(dens.min()) - at_fit),
        "familiar_share_between": between,
    }
