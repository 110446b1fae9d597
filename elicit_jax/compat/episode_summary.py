"""Per-episode summary of per-pair scores: the 5% rule's decisions, streamed.

The summary has one row per episode — operator, length, incompatible pairs, fraction
incompatible, mean M, ℓ and ν, the accept/reject decision and, when the scored demos carry it,
the episode's name in its source dataset (``source_episode``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from elicit_jax.data.demo_set import SOURCE_EPISODE


class EpisodeAccumulator:
    """Per-episode sums over streamed score batches (episodes contiguous, in order)."""

    def __init__(self, accept_fraction: float) -> None:
        self.accept_fraction = accept_fraction
        self._rows: dict[int, list[Any]] = {}
        self._names: dict[int, str] = {}

    def add(self, batch: Mapping[str, np.ndarray]) -> None:
        """Fold one batch of per-pair scores in."""
        ep = np.asarray(batch["episode"])
        if not len(ep):
            return
        starts = np.concatenate([[0], np.flatnonzero(np.diff(ep)) + 1])
        sums = {
            k: np.add.reduceat(np.asarray(batch[k], np.float64), starts)
            for k in ("incompatible", "compatibility", "likelihood", "novelty")
        }
        counts = np.diff(np.concatenate([starts, [len(ep)]]))
        names = batch.get(SOURCE_EPISODE)
        for i, s in enumerate(starts):
            if names is not None:
                self._names.setdefault(int(ep[s]), str(names[s]))
            row = self._rows.setdefault(int(ep[s]), [str(batch["operator"][s]), 0, 0, 0, 0, 0])
            row[1] += int(counts[i])
            row[2] += int(sums["incompatible"][i])
            row[3] += sums["compatibility"][i]
            row[4] += sums["likelihood"][i]
            row[5] += sums["novelty"][i]

    def columns(self) -> dict[str, np.ndarray]:
        """Per-episode columns: episode, operator, length, n_incompatible, fraction_incompatible,
        mean_compatibility, mean_likelihood, mean_novelty, accepted (and source_episode, the
        name in the source dataset, when the scored demos have it)."""
        ids = np.array(list(self._rows), dtype=np.int64)
        vals = list(self._rows.values())
        length = np.array([v[1] for v in vals], dtype=np.int64)
        n_inc = np.array([v[2] for v in vals], dtype=np.int64)
        safe = np.maximum(length, 1)
        names = (
            {"source_episode": np.array([self._names[int(e)] for e in ids], dtype=object)}
            if self._names
            else {}
        )
        return {
            "episode": ids,
            **names,
            "operator": np.array([v[0] for v in vals], dtype=object),
            "length": length,
            "n_incompatible": n_inc,
            "fraction_incompatible": (n_inc / safe).astype(np.float32),
            "mean_compatibility": (np.array([v[3] for v in vals]) / safe).astype(np.float32),
            "mean_likelihood": (np.array([v[4] for v in vals]) / safe).astype(np.float32),
            "mean_novelty": (np.array([v[5] for v in vals]) / safe).astype(np.float32),
            "accepted": ~(n_inc > self.accept_fraction * length),
        }


def summarise_episodes(pairs: Mapping[str, np.ndarray], accept_fraction: float) -> dict:
    """Per-episode summary of in-memory per-pair scores (see :class:`EpisodeAccumulator`)."""
    acc = EpisodeAccumulator(accept_fraction)
    acc.add(pairs)
    return acc.columns()


def episodes_table(episodes: Mapping[str, np.ndarray]) -> Any:
    """Arrow table of per-episode summary columns."""
    import pyarrow as pa

    text = ("operator", "source_episode")
    cols = {
        k: pa.array([str(x) for x in v], type=pa.string()) if k in text else pa.array(v)
        for k, v in episodes.items()
    }
    return pa.table(cols)
