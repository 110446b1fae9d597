"""Host-side preparation of training data: episode split, normalisation, sample windows.

Every model trains on *windows*: a window is ``seq_len`` row indices into the flat step
arrays plus a validity mask. Feed-forward models use windows of length 1 (one step each);
the LSTM uses windows starting at every step of every episode, padded (mask 0) past the end
of episodes shorter than the window.
"""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np

from elicit_jax.data.demos import Demos
from elicit_jax.errors import ElicitError
from elicit_jax.policy.base import normalization_stats

SPLIT_SEED = 0


@dataclasses.dataclass(frozen=True)
class TrainData:
    """Arrays a training run needs (numpy, host side).

    Attributes:
      obs: (N, O) normalised observations of all used rows.
      action: (N, A) actions.
      train_windows: (Nt, L) int32 row indices; train_mask: (Nt, L) float32.
      val_windows: (Nv, L) int32; val_mask: (Nv, L) float32 (Nv may be 0).
      obs_mean, obs_std: (O,) normalisation statistics from the training split.
      train_episodes, val_episodes: episode ids of each split.
    """

    obs: np.ndarray
    action: np.ndarray
    train_windows: np.ndarray
    train_mask: np.ndarray
    val_windows: np.ndarray
    val_mask: np.ndarray
    obs_mean: np.ndarray
    obs_std: np.ndarray
    train_episodes: tuple[int, ...]
    val_episodes: tuple[int, ...]

    @property
    def n_train(self) -> int:
        return int(self.train_windows.shape[0])

    @property
    def n_val(self) -> int:
        return int(self.val_windows.shape[0])


def action_stats(data: TrainData) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std ``(A,)`` of the training split's actions (float32), for action scaling."""
    rows = np.unique(data.train_windows[data.train_mask > 0])
    act = np.asarray(data.action, np.float64)[rows]
    return act.mean(axis=0).astype(np.float32), act.std(axis=0).astype(np.float32)


def split_episodes(ids: np.ndarray, val_fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic split of episode ids into (train, val), both sorted.

    ``round(val_fraction * E)`` episodes (at least 1 when the fraction is positive and there
    are two or more episodes) are drawn with a fixed seed, so every training seed validates
    on the same episodes.
    """
    ids = np.asarray(ids, np.int64)
    n_val = 0
    if val_fraction > 0 and len(ids) >= 2:
        n_val = min(max(1, round(val_fraction * len(ids))), len(ids) - 1)
    order = np.random.default_rng(SPLIT_SEED).permutation(len(ids))
    return np.sort(ids[order[n_val:]]), np.sort(ids[order[:n_val]])


def make_windows(bounds: list[tuple[int, int, int]], seq_len: int) -> tuple[np.ndarray, np.ndarray]:
    """Windows over episodes given as ``(id, start, stop)`` row ranges.

    Returns:
      (W, L) int32 row indices and (W, L) float32 mask; a window starts at every step ``t``
      with ``t + L <= T`` (one padded window for episodes shorter than L).
    """
    wins, masks = [], []
    offs = np.arange(seq_len)
    for _, start, stop in bounds:
        n_starts = max(stop - start - seq_len + 1, 1)
        idx = start + np.arange(n_starts)[:, None] + offs[None, :]
        masks.append((idx < stop).astype(np.float32))
        wins.append(np.minimum(idx, stop - 1).astype(np.int32))
    if not wins:
        return np.zeros((0, seq_len), np.int32), np.zeros((0, seq_len), np.float32)
    return np.concatenate(wins), np.concatenate(masks)


def prepare(demos: Demos, val_fraction: float, seq_len: int) -> TrainData:
    """Split ``demos`` by episode, normalise observations, and build sample windows."""
    bounds = demos.episode_bounds()
    if not bounds:
        raise ElicitError("no episodes to train on")
    train_ids, val_ids = split_episodes(np.array([e for e, _, _ in bounds]), val_fraction)
    train_b = [b for b in bounds if b[0] in set(train_ids.tolist())]
    val_b = [b for b in bounds if b[0] in set(val_ids.tolist())]
    train_rows = np.concatenate([np.arange(s, e) for _, s, e in train_b])
    mean, std = normalization_stats(demos.obs[train_rows])
    obs = ((demos.obs - mean) / std).astype(np.float32)
    tw, tm = make_windows(train_b, seq_len)
    vw, vm = make_windows(val_b, seq_len)
    return TrainData(
        obs=obs,
        action=np.asarray(demos.action, np.float32),
        train_windows=tw,
        train_mask=tm,
        val_windows=vw,
        val_mask=vm,
        obs_mean=mean,
        obs_std=std,
        train_episodes=tuple(int(i) for i in train_ids),
        val_episodes=tuple(int(i) for i in val_ids),
    )


def demos_sha256(demos: Demos) -> str:
    """Content hash of the arrays a policy is trained on (obs, action, episode ids)."""
    h = hashlib.sha256()
    for arr in (demos.obs, demos.action, demos.episode):
        arr = np.ascontiguousarray(arr)
        h.update(f"{arr.dtype}{arr.shape}".encode())
        h.update(arr.tobytes())
    return h.hexdigest()
