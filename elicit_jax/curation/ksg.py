"""The Kraskov–Stögbauer–Grassberger (KSG) k-nearest-neighbour estimator of mutual information,
per sample.

For N samples ``z_i = (x_i, y_i)`` the first KSG estimator is

    I(X; Y) ≈ ψ(k) + ψ(N) − ⟨ψ(n_x(i) + 1) + ψ(n_y(i) + 1)⟩,

where ``ε_i`` is the distance from ``z_i`` to its k-th nearest neighbour in the joint space
under ``‖z − z'‖ = max(‖x − x'‖, ‖y − y'‖)`` (each marginal distance Euclidean), ``n_x(i)`` the
number of other samples strictly closer than ``ε_i`` to ``x_i`` in the x space, likewise
``n_y(i)``, and ψ the digamma function. The average runs over samples, so each sample carries a
term ``ψ(k) + ψ(N) − ψ(n_x(i) + 1) − ψ(n_y(i) + 1)``: its contribution to the estimate. A sample
whose joint neighbourhood is tight compared with its marginal neighbourhoods (its y is
predictable from its x) has few marginal neighbours and a large term.

The neighbour search is exact and brute force: the queries are processed in chunks of rows
against the whole set inside one jitted ``lax.map`` (no approximate index, no subsampling), so
the cost is O(N² (d_x + d_y)) and the memory O(chunk × N). Distances come from
``‖a‖² + ‖b‖² − 2 a·b`` on centred data (one matrix product per chunk); the same computed
distances decide both ε and the counts, so the estimator's comparisons stay consistent.

Example:
    >>> terms = ksg_terms(x, y, ks=(3,))      # (N, 1)
    >>> float(terms.mean())                   # the KSG estimate of I(X; Y), in nats
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from elicit_jax.errors import ElicitError


def _check(x: np.ndarray, y: np.ndarray, ks: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, np.float32)
    y = np.asarray(y, np.float32)
    x = x[:, None] if x.ndim == 1 else x
    y = y[:, None] if y.ndim == 1 else y
    if x.ndim != 2 or y.ndim != 2 or len(x) != len(y):
        raise ElicitError(f"KSG needs x (N, dx) and y (N, dy) of equal N, got {x.shape}, {y.shape}")
    if not ks or min(ks) < 1:
        raise ElicitError(f"KSG neighbour counts k must be >= 1, got {tuple(ks)}")
    if len(x) <= max(ks):
        raise ElicitError(f"KSG with k = {max(ks)} needs more than {max(ks)} samples, got {len(x)}")
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise ElicitError("KSG got non-finite values")
    return x, y


def _sq_dists(q, ref):
    """Squared Euclidean distances ``(C, N)`` from query rows to every reference row."""
    import jax.numpy as jnp

    d2 = jnp.sum(q * q, 1)[:, None] + jnp.sum(ref * ref, 1)[None, :] - 2.0 * q @ ref.T
    return jnp.maximum(d2, 0.0)


def _smallest(d, kmax: int):
    """The ``kmax`` smallest entries of each row of ``d (C, N)``, ascending, with multiplicity
    (``lax.top_k`` lowers to a full sort on XLA:CPU; ``kmax`` argmin passes are far cheaper)."""
    import jax.numpy as jnp

    rows = jnp.arange(d.shape[0])
    out = []
    for _ in range(kmax):
        i = jnp.argmin(d, axis=1)
        out.append(d[rows, i])
        d = d.at[rows, i].set(jnp.inf)
    return jnp.stack(out, 1)


@functools.lru_cache(maxsize=8)
def _counts_fn(ks: tuple[int, ...], chunk: int):
    """Jitted ``fn(x (N, dx), y (N, dy), rows (C_total,)) -> eps², n_x, n_y``, each
    ``(C_total, len(ks))``, computed ``chunk`` query rows at a time. Squared distances keep
    every comparison of the estimator (the max norm of the joint space is monotone in them)."""
    import jax
    import jax.numpy as jnp

    k_idx = jnp.asarray([k - 1 for k in ks])

    def one_chunk(x: jax.Array, y: jax.Array, rows: jax.Array):
        self_ = jnp.arange(x.shape[0])[None, :] == rows[:, None]  # (C, N): the query itself
        dx = jnp.where(self_, jnp.inf, _sq_dists(x[rows], x))
        dy = jnp.where(self_, jnp.inf, _sq_dists(y[rows], y))
        eps = _smallest(jnp.maximum(dx, dy), max(ks))[:, k_idx]  # (C, len(ks))
        n_x = jnp.stack([jnp.sum(dx < eps[:, j, None], axis=1) for j in range(len(ks))], 1)
        n_y = jnp.stack([jnp.sum(dy < eps[:, j, None], axis=1) for j in range(len(ks))], 1)
        return eps, n_x, n_y

    def run(x: jax.Array, y: jax.Array, rows: jax.Array):
        per = jax.lax.map(lambda r: one_chunk(x, y, r), rows.reshape(-1, chunk))
        return jax.tree.map(lambda a: a.reshape(-1, len(ks)), per)

    return jax.jit(run)


def ksg_counts(
    x: np.ndarray, y: np.ndarray, ks: Sequence[int] = (3,), chunk: int = 256
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per sample and k: the joint k-NN distance ε and the marginal counts n_x, n_y.

    Args:
      x: (N, dx) or (N,) samples of X.
      y: (N, dy) or (N,) samples of Y.
      ks: neighbour counts.
      chunk: query rows per step (memory ~ 3 × chunk × N floats).

    Returns:
      ``eps (N, len(ks))`` float32, ``n_x`` and ``n_y`` ``(N, len(ks))`` int: the number of
      *other* samples strictly within ε in each marginal space.
    """
    x, y = _check(x, y, ks)
    n = len(x)
    chunk = max(1, min(int(chunk), n))
    total = -(-n // chunk) * chunk
    rows = np.minimum(np.arange(total), n - 1).astype(np.int32)  # pad with the last row
    x, y = x - x.mean(0), y - y.mean(0)  # smaller magnitudes: less rounding in the distances
    eps2, n_x, n_y = _counts_fn(tuple(int(k) for k in ks), chunk)(x, y, rows)
    return np.sqrt(np.asarray(eps2)[:n]), np.asarray(n_x)[:n], np.asarray(n_y)[:n]


def ksg_terms(
    x: np.ndarray, y: np.ndarray, ks: Sequence[int] = (3,), chunk: int = 256
) -> np.ndarray:
    """Per-sample KSG terms ``ψ(k) + ψ(N) − ψ(n_x + 1) − ψ(n_y + 1)``, one column per k.

    Their mean over samples is the KSG estimate of I(X; Y) in nats.

    Args:
      x: (N, dx) or (N,) samples of X.
      y: (N, dy) or (N,) samples of Y.
      ks: neighbour counts (DemInf averages its scores over several).
      chunk: query rows per step.

    Returns:
      (N, len(ks)) float64.
    """
    from scipy.special import digamma

    _, n_x, n_y = ksg_counts(x, y, ks, chunk)
    n = len(n_x)
    k = np.asarray(ks, np.float64)[None, :]
    return digamma(k) + digamma(n) - digamma(n_x + 1.0) - digamma(n_y + 1.0)


def ksg_mutual_information(x: np.ndarray, y: np.ndarray, k: int = 3, chunk: int = 256) -> float:
    """The KSG estimate of I(X; Y) in nats (mean of :func:`ksg_terms`)."""
    return float(ksg_terms(x, y, (k,), chunk).mean())
