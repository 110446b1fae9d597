"""Regrouping streamed row batches into the fixed-size chunks a jitted scorer compiles for.

Rows arrive in batches of any size (Parquet row groups); feed-forward scoring wants chunks of
exactly one size (:func:`row_chunks`, the last one padded by the caller with :func:`pad`),
recurrent scoring wants runs of complete episodes (:func:`episode_groups`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np


def balanced_chunk(n_rows: int, chunk_size: int, multiple: int = 256) -> int:
    """The chunk size that covers ``n_rows`` in as many chunks as ``chunk_size`` would, with
    the least padding: ``ceil(n / ceil(n / chunk))`` rounded up to ``multiple`` (and at most
    ``chunk_size``). Scores do not depend on the chunk size; this only saves padded work."""
    if n_rows <= 0:
        return chunk_size
    n_chunks = -(-n_rows // chunk_size)
    size = -(-n_rows // n_chunks)
    return min(chunk_size, -(-size // multiple) * multiple)


def concat(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Row-wise concatenation of column dicts with the same keys."""
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def take(rows: dict[str, np.ndarray], sl: slice) -> dict[str, np.ndarray]:
    """The rows ``sl`` of every column."""
    return {k: v[sl] for k, v in rows.items()}


def pad(x: np.ndarray, n: int) -> np.ndarray:
    """``x`` (m, ...) padded with zero rows to (n, ...)."""
    if len(x) == n:
        return x
    return np.concatenate([x, np.zeros((n - len(x), *x.shape[1:]), x.dtype)])


def row_chunks(
    batches: Iterable[dict[str, np.ndarray]], size: int
) -> Iterator[dict[str, np.ndarray]]:
    """Regroup row batches into chunks of exactly ``size`` rows (the last may be shorter)."""
    pending: list[dict[str, np.ndarray]] = []
    count = 0
    for b in batches:
        pending.append(b)
        count += len(b["episode"])
        if count >= size:
            rows = concat(pending)
            stop = (count // size) * size
            for s in range(0, stop, size):
                yield take(rows, slice(s, s + size))
            pending = [take(rows, slice(stop, None))] if stop < count else []
            count -= stop
    if count:
        yield concat(pending)


def episode_groups(
    batches: Iterable[dict[str, np.ndarray]], size: int
) -> Iterator[dict[str, np.ndarray]]:
    """Regroup row batches into runs of complete episodes of at least ``size`` rows."""
    pending: list[dict[str, np.ndarray]] = []
    for b in batches:
        pending.append(b)
        rows = concat(pending)
        ep = rows["episode"]
        last = np.flatnonzero(ep != ep[-1])
        if len(last) and last[-1] + 1 >= size:
            cut = int(last[-1]) + 1
            yield take(rows, slice(0, cut))
            pending = [take(rows, slice(cut, None))]
        else:
            pending = [rows]
    if pending and len(pending[0]["episode"]):
        yield concat(pending)
