"""Feedback primitives: where a demonstration went wrong, and which base demo to show instead.

* :func:`top_windows`: the ``k`` (default 3) non-overlapping windows of highest mean
  incompatibility ``1 − M`` (greedy: best window first, then the best window not overlapping
  any chosen one; ties go to the earliest start).
* :func:`retrieve`: for each window of states, the base demonstration (and the segment of it)
  nearest in state space, states normalised by the base data's per-dim mean and std:
  ``l2`` (default; the paper): the mean Euclidean distance between the window and an equally
  long base segment, minimised over the segment start; ``dtw`` (the original code):
  subsequence dynamic time warping — the cheapest monotone alignment of the whole window to
  any base segment, cost per window step.

  Each window gets its own segment: a base segment overlapping one already retrieved for a
  worse window is passed over for the next best, so two windows never replay the same base
  motion (``distinct=False``: the nearest segment for each, shared or not).

:func:`episode_feedback` combines both for one demonstration against a base ``Demos``.

Example:
    >>> wins = top_windows(scores["compatibility"][episode_rows], window=10)
    >>> matches = retrieve([obs[w.start:w.stop] for w in wins], base_episodes, method="dtw")
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np

from elicit_jax.errors import ElicitError

STD_FLOOR = 1e-6


@dataclasses.dataclass(frozen=True)
class Window:
    """Steps ``start:stop`` of an episode and their mean incompatibility ``1 − M``."""

    start: int
    stop: int
    score: float


@dataclasses.dataclass(frozen=True)
class Match:
    """The base episode (by position in the list given) and segment nearest to a window."""

    episode: int
    start: int
    stop: int
    distance: float


def top_windows(compatibility: np.ndarray, window: int = 10, k: int = 3) -> list[Window]:
    """The ``k`` non-overlapping windows of highest mean ``1 − M``.

    Args:
      compatibility: (T,) M of each step of one episode.
      window: window length (shortened to T for shorter episodes).
      k: how many windows at most.

    Returns:
      Windows, best first (fewer than ``k`` when the episode is too short).
    """
    m = np.asarray(compatibility, np.float64)
    if m.ndim != 1 or len(m) == 0:
        raise ElicitError("need a non-empty 1-D array of compatibility values")
    if window < 1 or k < 1:
        raise ElicitError(f"window and k must be >= 1, got window={window}, k={k}")
    w = min(window, len(m))
    csum = np.concatenate([[0.0], np.cumsum(1.0 - m)])
    means = (csum[w:] - csum[:-w]) / w  # (T - w + 1,) mean over steps s..s+w-1
    free = np.ones(len(means), bool)
    out: list[Window] = []
    while len(out) < k and free.any():
        s = int(np.argmax(np.where(free, means, -np.inf)))
        out.append(Window(s, s + w, float(means[s])))
        free[max(0, s - w + 1) : s + w] = False
    return out


def normalizer(base_obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-dim mean and std ``(O,)`` of base states ``(N, O)``; stds below 1e-6 become 1."""
    x = np.asarray(base_obs, np.float64)
    std = x.std(axis=0)
    return x.mean(axis=0), np.where(std < STD_FLOOR, 1.0, std)


def l2_candidates(query: np.ndarray, episode: np.ndarray) -> tuple[np.ndarray, ...]:
    """Every segment of ``episode`` (T, O) as long as ``query`` (W, O), with its mean
    Euclidean distance to the query.

    Returns:
      ``(costs, starts, stops)``, one entry per segment start (when T < W: one entry, the
      whole episode against the best-matching T steps of the query).
    """
    q, e = np.asarray(query, np.float64), np.asarray(episode, np.float64)
    w = min(len(q), len(e))
    if len(e) >= len(q):
        idx = np.arange(len(e) - w + 1)[:, None] + np.arange(w)[None, :]  # (S, w)
        d = np.linalg.norm(e[idx] - q[None, :w], axis=-1).mean(axis=1)
        starts = np.arange(len(d))
        return d, starts, starts + w
    idx = np.arange(len(q) - w + 1)[:, None] + np.arange(w)[None, :]
    d = np.linalg.norm(q[idx] - e[None, :], axis=-1).mean(axis=1)
    return np.array([d.min()]), np.array([0]), np.array([len(e)])


def l2_distance(query: np.ndarray, episode: np.ndarray) -> tuple[float, int, int]:
    """Best aligned segment by mean Euclidean distance.

    Args:
      query: (W, O) window of states.
      episode: (T, O) base episode (same normalisation).

    Returns:
      ``(distance, start, stop)`` of the best segment of ``episode`` (when T < W, the
      episode is compared with the best-matching T steps of the query).
    """
    d, starts, stops = l2_candidates(query, episode)
    s = int(np.argmin(d))
    return float(d[s]), int(starts[s]), int(stops[s])


def dtw_candidates(query: np.ndarray, episode: np.ndarray) -> tuple[np.ndarray, ...]:
    """Subsequence DTW of ``query`` (W, O) against ``episode`` (T, O), for every end step.

    ``D[i, j] = c(i, j) + min(D[i−1, j], D[i, j−1], D[i−1, j−1])`` with a free start
    (``D[−1, j] = 0``), where ``c`` is the Euclidean distance of states. Each row is solved
    in closed form — ``D[i, j] = S_j + min_{k ≤ j}(a_k − S_{k−1})`` with ``S`` the running
    sum of the row's costs and ``a_k = min(D[i−1, k], D[i−1, k−1])`` — so the work is
    O(W·T) numpy.

    Returns:
      ``(costs, starts, stops)``: per end step ``j``, the cheapest alignment's cost per
      window step, its first base step and ``j + 1``.
    """
    q, e = np.asarray(query, np.float64), np.asarray(episode, np.float64)
    cost = np.linalg.norm(q[:, None, :] - e[None, :, :], axis=-1)  # (W, T)
    t = cost.shape[1]
    cols = np.arange(t)
    prev = np.zeros(t)
    prev_start = cols.copy()
    for i in range(cost.shape[0]):
        if i == 0:
            a, a_start = np.zeros(t), cols.copy()
        else:
            diag = np.concatenate([[np.inf], prev[:-1]])
            diag_start = np.concatenate([[0], prev_start[:-1]])
            use_diag = diag < prev
            a = np.where(use_diag, diag, prev)
            a_start = np.where(use_diag, diag_start, prev_start)
        s = np.cumsum(cost[i])
        s_before = np.concatenate([[0.0], s[:-1]])
        v = a - s_before
        run = np.minimum.accumulate(v)
        arg = np.maximum.accumulate(np.where(v <= run, cols, 0))
        prev, prev_start = s + run, a_start[arg]
    return prev / cost.shape[0], prev_start, cols + 1


def dtw_distance(query: np.ndarray, episode: np.ndarray) -> tuple[float, int, int]:
    """Subsequence DTW (:func:`dtw_candidates`) with a free end: the cheapest end step.

    Returns:
      ``(cost / W, start, stop)`` of the aligned base segment.
    """
    d, starts, stops = dtw_candidates(query, episode)
    j = int(np.argmin(d))
    return float(d[j]), int(starts[j]), int(stops[j])


def _best_free(
    cands: tuple[np.ndarray, ...], taken: Sequence[tuple[int, int]]
) -> tuple[float, int, int] | None:
    """The cheapest candidate segment overlapping none of ``taken`` (None when all do)."""
    d, starts, stops = cands
    free = np.ones(len(d), bool)
    for a, b in taken:
        free &= ~((starts < b) & (a < stops))
    if not free.any():
        return None
    j = int(np.argmin(np.where(free, d, np.inf)))
    return float(d[j]), int(starts[j]), int(stops[j])


def retrieve(
    windows: Sequence[np.ndarray],
    base_episodes: Sequence[np.ndarray],
    method: Literal["l2", "dtw"] = "l2",
    stats: tuple[np.ndarray, np.ndarray] | None = None,
    distinct: bool = True,
) -> list[Match]:
    """The nearest base episode and segment for each window of states.

    Args:
      windows: each (W, O) raw states of a flagged window, worst first.
      base_episodes: each (T, O) raw states of a base demonstration.
      method: ``l2`` or ``dtw``.
      stats: normalisation (mean, std); default: from the concatenated base states.
      distinct: each window gets its own segment: in window order, a base segment that
        overlaps one chosen for an earlier window is passed over for the next best (so two
        windows never replay the same base motion), unless every segment overlaps one.

    Returns:
      One :class:`Match` per window (``episode`` indexes ``base_episodes``; ties go to the
      earliest episode, then the earliest segment).
    """
    if method not in ("l2", "dtw"):
        raise ElicitError(f"unknown retrieval method '{method}' (choose l2 or dtw)")
    if not base_episodes:
        raise ElicitError("no base demonstrations to retrieve from")
    mean, std = stats if stats is not None else normalizer(np.concatenate(base_episodes))
    base = [(np.asarray(b, np.float64) - mean) / std for b in base_episodes]
    candidates = l2_candidates if method == "l2" else dtw_candidates
    taken: dict[int, list[tuple[int, int]]] = {}
    out = []
    for w in windows:
        q = np.asarray(w, np.float64)
        if q.ndim != 2 or q.shape[1] != base[0].shape[1] or not len(q):
            raise ElicitError(f"window of shape {np.shape(w)} does not match base states")
        q = (q - mean) / std
        cands = [candidates(q, b) for b in base]
        found = [
            (r, n)
            for n, c in enumerate(cands)
            if (r := _best_free(c, taken.get(n, []) if distinct else [])) is not None
        ]
        if not found:  # every segment already shown: the nearest one again
            found = [(_best_free(c, []), n) for n, c in enumerate(cands)]
        (d, s, e), n = min(found, key=lambda r: (r[0][0], r[1]))
        taken.setdefault(n, []).append((s, e))
        out.append(Match(n, s, e, d))
    return out


@dataclasses.dataclass(frozen=True)
class Feedback:
    """One flagged window of a demonstration and the base segment to show for it.

    Attributes:
      window: the flagged steps and their mean incompatibility.
      base_episode: episode id (in the base demonstrations) of the nearest base demo.
      base_start: first step of the matching base segment.
      base_stop: one past its last step.
      distance: L2 or DTW distance (normalised states) of the match.
    """

    window: Window
    base_episode: int
    base_start: int
    base_stop: int
    distance: float


def episode_feedback(
    compatibility: np.ndarray,
    obs: np.ndarray,
    base: Any,
    *,
    window: int = 10,
    k: int = 3,
    method: Literal["l2", "dtw"] = "l2",
) -> list[Feedback]:
    """The paper's feedback for one demonstration: its ``k`` worst windows, each paired with
    the nearest segment of a base demonstration.

    Args:
      compatibility: (T,) M of each step of the demonstration.
      obs: (T, O) its raw states.
      base: the base :class:`~elicit_jax.data.demos.Demos` (normalisation from its states).
      window: window length.
      k: number of windows.
      method: ``l2`` (paper) or ``dtw`` (original code).

    Returns:
      One :class:`Feedback` per window, worst first.
    """
    obs = np.asarray(obs)
    if len(obs) != len(np.asarray(compatibility)):
        raise ElicitError(f"{len(compatibility)} compatibility values for {len(obs)} states")
    bounds = base.episode_bounds()
    episodes = [base.obs[s:e] for _, s, e in bounds]
    wins = top_windows(compatibility, window, k)
    matches = retrieve(
        [obs[w.start : w.stop] for w in wins], episodes, method, normalizer(base.obs)
    )
    return [
        Feedback(w, bounds[m.episode][0], m.start, m.stop, m.distance)
        for w, m in zip(wins, matches, strict=True)
    ]
