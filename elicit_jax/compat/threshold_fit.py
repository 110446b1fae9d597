"""Fit the thresholds (λ, η) from labelled contrast sets of demonstrations.

The paper assumes a few trajectories labelled *a priori* as compatible and incompatible and
"regresses" (λ, η) from the 2-D map without saying how. Our objective works on the decisions
that matter, one per demonstration: a demonstration is rejected when more than
``accept_fraction`` (5%) of its pairs are incompatible (``ℓ > λ`` and ``ν < η``). Candidate
thresholds form a grid (:func:`candidates`): for the ``(i + ½)/G`` quantiles of the contrast
pairs' ℓ values (``G = grid_size``) λ takes the midpoint between the observed values on either
side of the quantile, never an observed value itself (pairs repeated by a paused operator would
otherwise flip at once with the tie rule); η the same on the ν values; duplicates removed. For
each candidate we compute the **balanced
accuracy** of the decisions — the mean of the fraction of compatible demonstrations accepted
and the fraction of incompatible ones rejected — and keep the candidates that maximise it.
Among those, we pick the one with the **widest margin**: the largest ``r`` such that every
candidate within ``r`` grid steps in both λ and η (a ``(2r+1) × (2r+1)`` block, in quantile
space, inside the grid) also reaches the maximum — the thresholds can move ``r/G`` in quantile
in any direction without changing a single contrast decision's contribution to the score.
Remaining ties go to the larger λ, then the smaller η (the fewest rejections). The fit is
deterministic: no randomness, a fixed grid, a fixed tie order. It fails with a clear error when
a set is empty, the sets overlap, or no candidate does better than chance (balanced accuracy
0.5). With more than one demonstration in a set we also report leave-one-out accuracy: each
such demonstration is held out, the thresholds refitted on the rest, and the held-out decision
checked. Whether the result can be trusted at all is judged in :mod:`elicit_jax.compat.trust`.

Example:
    >>> fit = fit_thresholds(ell, nu, episode, labels)   # labels: episode id -> True/False
    >>> fit.thresholds.pair, fit.balanced_accuracy

The :class:`~elicit_jax.compat.thresholds.Thresholds` value and its file are in
:mod:`elicit_jax.compat.thresholds`; this module only searches the grid.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from elicit_jax.compat.measures import check_accept_fraction, is_incompatible
from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.errors import ElicitError


@dataclasses.dataclass(frozen=True)
class FitConfig:
    """Threshold fitting settings.

    Attributes:
      accept_fraction: the accept/reject rule's fraction (paper: 5%).
      grid_size: quantile levels per axis of the candidate grid.
    """

    accept_fraction: float = 0.05
    grid_size: int = 64

    def __post_init__(self) -> None:
        if self.grid_size < 2:
            raise ElicitError(f"grid size must be >= 2, got {self.grid_size}")
        check_accept_fraction(self.accept_fraction)


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Fitted thresholds and how well they separate the contrast sets.

    Attributes:
      thresholds: the fitted (λ, η) (source ``fit``).
      balanced_accuracy: on the contrast demonstrations.
      margin_steps: the margin r in grid steps (see module docstring).
      margin_quantile: r / grid_size.
      lambda_range: λ values spanned by the margin block.
      eta_range: η values spanned by the margin block.
      loo_accuracy: leave-one-out accuracy, or None when both sets hold one demonstration.
      n_loo: demonstrations held out.
      episodes: per contrast demonstration: episode, label, fraction incompatible, rejected.
    """

    thresholds: Thresholds
    balanced_accuracy: float
    margin_steps: int
    margin_quantile: float
    lambda_range: tuple[float, float]
    eta_range: tuple[float, float]
    loo_accuracy: float | None
    n_loo: int
    episodes: Mapping[str, np.ndarray]


def candidates(values: np.ndarray, size: int, upper: bool = False) -> np.ndarray:
    """Sorted candidate thresholds between the observed ``values`` (N,), about ``size`` of them.

    For each ``(i + ½)/size`` quantile ``q`` with observed neighbours ``a ≤ q < b`` the
    candidate is the midpoint of ``a`` and ``b`` (above the largest value when ``q`` is the
    maximum). Candidates are float32-representable, so scores stored as float32 compare with
    them exactly as here; when ``a`` and ``b`` are adjacent float32 numbers and no midpoint
    exists, the candidate is ``a`` for a ``>`` test (``upper=False``, λ) or ``b`` for a ``<``
    test (``upper=True``, η), which decides every pair the same way as a midpoint would.
    """
    v = np.asarray(values, np.float32)
    u = np.unique(v)
    q = np.quantile(v.astype(np.float64), (np.arange(size) + 0.5) / size)
    k = np.searchsorted(u.astype(np.float64), q, side="right")  # u[k-1] <= q < u[k]
    a = u[k - 1]
    top = np.nextafter(u[-1], np.float32(np.inf))
    b = np.where(k < len(u), u[np.minimum(k, len(u) - 1)], top)
    mid = ((a.astype(np.float64) + b.astype(np.float64)) / 2).astype(np.float32)
    mid = np.where((mid > a) & (mid < b), mid, b if upper else a)
    return np.unique(np.where(k < len(u), mid, top)).astype(np.float64)


def incompatible_counts(
    ell: np.ndarray,
    nu: np.ndarray,
    index: np.ndarray,
    n_ep: int,
    lams: np.ndarray,
    etas: np.ndarray,
) -> np.ndarray:
    """Incompatible pairs per episode for every candidate: ``(E, len(lams), len(etas))``.

    A pair counts for ``(λ_i, η_j)`` when ``ℓ > λ_i`` and ``ν < η_j``.
    """
    li = np.searchsorted(lams, ell, side="left")  # pair counts for λ indices < li
    ej = np.searchsorted(etas, nu, side="right")  # pair familiar for η indices >= ej
    hist = np.zeros((n_ep, len(lams) + 1, len(etas) + 1), np.int32)
    np.add.at(hist, (index, li, ej), 1)
    cum = np.cumsum(hist, axis=2)
    rev = np.cumsum(cum[:, ::-1, :], axis=1)[:, ::-1, :]
    return rev[:, 1:, : len(etas)]


def _margins(mask: np.ndarray) -> np.ndarray:
    """Chebyshev radius of the largest all-true block centred at each cell (-1 where false)."""
    out = np.full(mask.shape, -1, np.int32)
    cur, r = mask.copy(), 0
    while cur.any():
        out[cur] = r
        pad = np.pad(cur, 1, constant_values=False)
        nxt = np.ones_like(cur)
        for di in (0, 1, 2):
            for dj in (0, 1, 2):
                nxt &= pad[di : di + cur.shape[0], dj : dj + cur.shape[1]]
        cur, r = nxt, r + 1
    return out


def _prepare(
    ell: np.ndarray, nu: np.ndarray, episode: np.ndarray, labels: Mapping[int, bool]
) -> tuple[np.ndarray, ...]:
    keep = np.isin(episode, np.array(list(labels), dtype=np.int64))
    ids, index = np.unique(episode[keep], return_inverse=True)
    y = np.array([bool(labels[int(i)]) for i in ids])
    lengths = np.bincount(index, minlength=len(ids))
    # scores are stored as float32; candidates are float32 numbers, so compare in float32
    return ell[keep].astype(np.float32), nu[keep].astype(np.float32), index, ids, y, lengths


def _check_sets(y: np.ndarray) -> None:
    if not y.any():
        raise ElicitError("the compatible set holds no demonstrations in these scores")
    if y.all():
        raise ElicitError("the incompatible set holds no demonstrations in these scores")


def _balanced_accuracy(reject: np.ndarray, y: np.ndarray) -> np.ndarray:
    acc = ~reject[y]
    rej = reject[~y]
    return 0.5 * (acc.mean(axis=0) + rej.mean(axis=0))


def fit_thresholds(
    ell: np.ndarray,
    nu: np.ndarray,
    episode: np.ndarray,
    labels: Mapping[int, bool],
    config: FitConfig = FitConfig(),
    leave_one_out: bool = True,
) -> FitResult:
    """Fit (λ, η) to accept the compatible and reject the incompatible demonstrations.

    Args:
      ell: (N,) likelihood errors of all pairs (pairs outside the sets are ignored).
      nu: (N,) novelties.
      episode: (N,) episode id of each pair.
      labels: episode id -> True (compatible) / False (incompatible).
      config: fraction and grid size.
      leave_one_out: also compute leave-one-out accuracy.

    Returns:
      A :class:`FitResult`.

    Raises:
      ElicitError: an empty set, or no candidate better than chance.
    """
    ell, nu, index, ids, y, lengths = _prepare(
        np.asarray(ell), np.asarray(nu), np.asarray(episode), labels
    )
    _check_sets(y)
    lams = candidates(ell, config.grid_size)
    etas = candidates(nu, config.grid_size, upper=True)
    counts = incompatible_counts(ell, nu, index, len(ids), lams, etas)
    reject = counts > config.accept_fraction * lengths[:, None, None]
    ba = _balanced_accuracy(reject, y)
    best = float(ba.max())
    if best <= 0.5 + 1e-12:
        raise ElicitError(
            "no (lambda, eta) separates the contrast sets better than chance (balanced "
            "accuracy 0.5): are the sets mislabelled or indistinguishable under this policy?"
        )
    radius = _margins(ba >= best - 1e-12)
    i_idx, j_idx = np.meshgrid(np.arange(len(lams)), np.arange(len(etas)), indexing="ij")
    order = np.lexsort((j_idx.ravel(), -i_idx.ravel(), -radius.ravel()))
    i, j = np.unravel_index(order[0], radius.shape)
    r = int(radius[i, j])
    frac = counts[:, i, j] / lengths
    loo = _leave_one_out(ell, nu, index, ids, y, config) if leave_one_out else (None, 0)
    return FitResult(
        thresholds=Thresholds(float(lams[i]), float(etas[j]), "fit"),
        balanced_accuracy=best,
        margin_steps=r,
        margin_quantile=r / config.grid_size,
        lambda_range=(float(lams[i - r]), float(lams[i + r])),
        eta_range=(float(etas[j - r]), float(etas[j + r])),
        loo_accuracy=loo[0],
        n_loo=loo[1],
        episodes={
            "episode": ids,
            "compatible": y,
            "fraction_incompatible": frac,
            "rejected": reject[:, i, j],
        },
    )


def _leave_one_out(
    ell: np.ndarray,
    nu: np.ndarray,
    index: np.ndarray,
    ids: np.ndarray,
    y: np.ndarray,
    config: FitConfig,
) -> tuple[float | None, int]:
    """Accuracy of held-out decisions over the demonstrations of sets larger than one."""
    held = [k for k in range(len(ids)) if (y == y[k]).sum() > 1]
    if not held:
        return None, 0
    correct = 0
    for k in held:
        rest = {int(ids[m]): bool(y[m]) for m in range(len(ids)) if m != k}
        try:
            fit = fit_thresholds(ell, nu, ids[index], rest, config, leave_one_out=False)
        except ElicitError:
            continue
        sel = index == k
        n_inc = int(is_incompatible(ell[sel], nu[sel], *fit.thresholds.pair).sum())
        rejected = n_inc > config.accept_fraction * int(sel.sum())
        correct += int(rejected != y[k])
    return correct / len(held), len(held)


def evaluate_thresholds(
    ell: np.ndarray,
    nu: np.ndarray,
    episode: np.ndarray,
    labels: Mapping[int, bool],
    thresholds: Thresholds,
    accept_fraction: float = 0.05,
) -> tuple[float, dict[str, np.ndarray]]:
    """Balanced accuracy and per-demonstration decisions of given thresholds on the sets."""
    ell, nu, index, ids, y, lengths = _prepare(
        np.asarray(ell), np.asarray(nu), np.asarray(episode), labels
    )
    _check_sets(y)
    inc = is_incompatible(ell, nu, *thresholds.pair)
    n_inc = np.bincount(index, weights=inc, minlength=len(ids))
    reject = n_inc > accept_fraction * lengths
    ba = float(_balanced_accuracy(reject[:, None], y)[0])
    return ba, {
        "episode": ids,
        "compatible": y,
        "fraction_incompatible": n_inc / lengths,
        "rejected": reject,
    }


def operator_rejections(
    ell: np.ndarray,
    nu: np.ndarray,
    episode: np.ndarray,
    operator: np.ndarray,
    thresholds: Thresholds,
    accept_fraction: float = 0.05,
) -> dict[str, dict[str, int]]:
    """Per operator: pairs, incompatible pairs, episodes and rejected episodes under (λ, η)."""
    inc = is_incompatible(np.asarray(ell), np.asarray(nu), *thresholds.pair)
    ids, index = np.unique(episode, return_inverse=True)
    n_inc = np.bincount(index, weights=inc, minlength=len(ids))
    lengths = np.bincount(index, minlength=len(ids))
    first = np.zeros(len(ids), np.int64)
    first[index[::-1]] = np.arange(len(index))[::-1]
    ep_op = np.asarray(operator)[first].astype(str)
    rejected = n_inc > accept_fraction * lengths
    ops = np.asarray(operator).astype(str)
    out = {}
    for op in sorted(set(ep_op.tolist())):
        sel = ep_op == op
        out[op] = {
            "pairs": int((ops == op).sum()),
            "incompatible_pairs": int(inc[ops == op].sum()),
            "episodes": int(sel.sum()),
            "rejected_episodes": int(rejected[sel].sum()),
        }
    return out
