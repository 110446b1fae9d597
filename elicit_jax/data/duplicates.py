"""Duplicate episodes, found by content: the same observations and actions, step for step.

Two imports of one dataset, ``demos concat`` of overlapping files, or ``filter --base
base.parquet --demos all.parquet`` (D_base inside D_new) would otherwise train on, and export,
the same demonstration twice. An episode's identity is :func:`~elicit_jax.data.demos.
episode_digest` of its ``obs`` and ``action`` (ids, operator labels, rewards and source names
do not count).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from elicit_jax.data.demo_set import Demos
from elicit_jax.data.demos import episode_digest


@dataclasses.dataclass(frozen=True)
class Duplicate:
    """Episode ``episode`` of part ``part`` repeats episode ``of_episode`` of part
    ``of_part`` (parts are indices into the sequence of demo sets searched)."""

    part: int
    episode: int
    of_part: int
    of_episode: int


def episode_digests(demos: Demos) -> dict[int, str]:
    """Episode id -> content hash of its observations and actions, in row order."""
    return {
        e: episode_digest(demos.obs[s:t], demos.action[s:t]) for e, s, t in demos.episode_bounds()
    }


def find_duplicates(parts: Sequence[Demos]) -> list[Duplicate]:
    """Every episode that repeats an earlier one (earlier in its own part, or in an earlier
    part), in order; the first copy is never listed."""
    first: dict[str, tuple[int, int]] = {}
    out = []
    for i, demos in enumerate(parts):
        for e, digest in episode_digests(demos).items():
            if digest in first:
                out.append(Duplicate(i, e, *first[digest]))
            else:
                first[digest] = (i, e)
    return out


def duplicates_of(new: Demos, base: Demos) -> dict[int, int]:
    """Episodes of ``new`` identical to an episode of ``base``: new id -> base id."""
    seen = {d: e for e, d in reversed(list(episode_digests(base).items()))}
    return {e: seen[d] for e, d in episode_digests(new).items() if d in seen}


def describe(dups: Sequence[Duplicate], names: Sequence[str], limit: int = 3) -> str:
    """``episode 3 of b.parquet repeats episode 0 of a.parquet, ... (and N more)``."""
    shown = [
        f"episode {d.episode} of {names[d.part]} repeats episode {d.of_episode} of "
        f"{names[d.of_part]}"
        for d in dups[:limit]
    ]
    more = f" (and {len(dups) - limit} more)" if len(dups) > limit else ""
    return "; ".join(shown) + more


def drop_rows(demos: Demos, episodes: Sequence[int] | np.ndarray) -> np.ndarray:
    """(N,) bool: the rows of these episodes."""
    return np.isin(demos.episode, np.asarray(list(episodes), dtype=np.int64))


def duplicate_reasons(
    demos: Demos, dups: dict[int, int], drop: np.ndarray, reason: str
) -> np.ndarray:
    """(N,) the drop log's reason of each row: ``reason``, or for an episode identical to a
    D_base episode ``duplicate of --base episode B`` (dropped whatever its scores)."""
    out = np.where(drop, reason, "").astype(object)
    for e, b in dups.items():
        out[demos.episode == e] = f"duplicate of --base episode {b}"
    return out
