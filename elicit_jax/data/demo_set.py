"""The in-memory demonstration set: :class:`Demos` and its named observation slices.

This module holds only the type and its row/episode selections; reading, writing and
validating the Parquet artifact live in :mod:`elicit_jax.data.demos` and
:mod:`elicit_jax.data.validation`, which build on it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

SOURCE_EPISODE = "source_episode"
TASK_COLUMN = "task"  # per-step task text, when a dataset records one per frame (LeRobot)
ARRAY_FIELDS = ("obs", "action", "episode", "operator", "step", "reward", "success")


@dataclasses.dataclass(frozen=True)
class ObsField:
    """A named slice of the observation vector, e.g. ``robot0_eef_pos`` = ``obs[:, 0:3]``."""

    name: str
    start: int
    stop: int

    @property
    def size(self) -> int:
        return self.stop - self.start


def fields_from_sizes(sizes: Sequence[tuple[str, int]]) -> tuple[ObsField, ...]:
    """Contiguous fields from ``(name, size)`` pairs, in order."""
    out, start = [], 0
    for name, size in sizes:
        out.append(ObsField(name, start, start + int(size)))
        start += int(size)
    return tuple(out)


@dataclasses.dataclass(frozen=True)
class Demos:
    """A set of demonstrations held as flat per-step arrays (N steps in all).

    Attributes:
      obs: (N, obs_dim) float32.
      action: (N, act_dim) float32.
      episode: (N,) int64 episode ids; each episode's rows are contiguous.
      operator: (N,) str operator name of each step's episode.
      step: (N,) int32 step index within the episode, 0..T-1.
      reward: (N,) float32.
      success: (N,) bool, the episode's outcome repeated on each of its steps.
      task: task name.
      obs_fields: named slices of ``obs``.
      action_low: lower action bound (scalar or per dim).
      action_high: upper action bound (scalar or per dim).
      provenance: where the data came from (source, its sha256, importer, time).
      extra: optional extra per-step columns, name -> (N, ...) array.
    """

    obs: np.ndarray
    action: np.ndarray
    episode: np.ndarray
    operator: np.ndarray
    step: np.ndarray
    reward: np.ndarray
    success: np.ndarray
    task: str = "unknown"
    obs_fields: tuple[ObsField, ...] = ()
    action_low: float | tuple[float, ...] = -1.0
    action_high: float | tuple[float, ...] = 1.0
    provenance: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    extra: Mapping[str, np.ndarray] = dataclasses.field(default_factory=dict)

    @property
    def obs_dim(self) -> int:
        return int(self.obs.shape[1])

    @property
    def action_dim(self) -> int:
        return int(self.action.shape[1])

    @property
    def n_steps(self) -> int:
        return int(self.obs.shape[0])

    def episode_bounds(self) -> list[tuple[int, int, int]]:
        """``(episode_id, start, stop)`` of each episode, in row order."""
        if self.n_steps == 0:
            return []
        change = np.flatnonzero(np.diff(self.episode)) + 1
        starts = np.concatenate([[0], change])
        stops = np.concatenate([change, [self.n_steps]])
        return [(int(self.episode[s]), int(s), int(e)) for s, e in zip(starts, stops, strict=True)]

    @property
    def episode_ids(self) -> np.ndarray:
        return np.array([e for e, _, _ in self.episode_bounds()], dtype=np.int64)

    @property
    def n_episodes(self) -> int:
        return len(self.episode_bounds())

    def episode_operator(self) -> dict[int, str]:
        """Episode id -> operator name."""
        return {e: str(self.operator[s]) for e, s, _ in self.episode_bounds()}

    def select(self, mask: np.ndarray) -> Demos:
        """Rows where ``mask`` (N,) is true; metadata kept."""
        mask = np.asarray(mask, dtype=bool)
        arrays = {k: getattr(self, k)[mask] for k in ARRAY_FIELDS}
        extra = {k: v[mask] for k, v in self.extra.items()}
        return dataclasses.replace(self, **arrays, extra=extra)

    def select_episodes(self, ids: Sequence[int] | np.ndarray) -> Demos:
        """The given episodes, in their original order."""
        return self.select(np.isin(self.episode, np.asarray(ids, dtype=np.int64)))

    def select_operators(self, names: Sequence[str]) -> Demos:
        """Episodes of the given operators."""
        return self.select(np.isin(self.operator.astype(str), list(names)))

    def episodes(self) -> list[dict[str, np.ndarray]]:
        """Per-episode dicts of arrays (obs, action, reward, ...)."""
        out = []
        for _, s, e in self.episode_bounds():
            ep = {k: getattr(self, k)[s:e] for k in ARRAY_FIELDS}
            ep.update({k: v[s:e] for k, v in self.extra.items()})
            out.append(ep)
        return out
