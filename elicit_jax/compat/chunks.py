"""Regrouping streamed row batches into the fixed-size chunks a jitted scorer compiles for.

Rows arrive in batches of any size (Parquet row groups); feed-forward scoring wants chunks of
exactly one size (:func:`row_chunks`, the last one padded by the caller with :func:`pad`),
recurrent scoring wants runs of complete episodes (:func:`episode_groups`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np


def balanced_chunk(n_rows: int, chunk_size: int, steps_per_octave: int = 8) -> int:
    """The chunk size that covers ``n_rows`` in as many chunks as ``chunk_size`` would, with
    little padding: ``ceil(n / ceil(n / chunk))`` rounded up to a multiple of 1/8 of the
    power of two below it (at least 16), and at most ``chunk_size``. Padding then wastes at
    most an eighth of a chunk (a 90-step episode is scored as 96 rows, not 256), and a run
    compiles one of at most 8 sizes per doubling. This only saves padded work."""
    if n_rows <= 0:
        return chunk_size
    n_chunks = -(-n_rows // chunk_size)
    size = -(-n_rows // n_chunks)
    step = max(16, (1 << (size.bit_length() - 1)) // steps_per_octave)
    return min(chunk_size, -(-size // step) * step)


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
