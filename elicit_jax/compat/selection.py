"""Episode selections written on the command line: ``operator:NAME[,NAME]``,
``episodes:ID[,ID]`` (with ranges, ``episodes:0-4,7``) or ``label:COLUMN=VALUE``.

``label`` reads a per-pair column of the scores file (``success`` and the demonstrations'
scalar extra columns are copied there by ``score``); an episode is selected when every one of
its pairs has that value (compared as lower-case text, so ``label:success=true`` works).

Example:
    >>> sel = parse_selection("operator:alice,bob")
    >>> ids = select_episodes(sel, scores_columns)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from elicit_jax.data.selection import parse_episode_ids
from elicit_jax.errors import ElicitError

KINDS = ("operator", "episodes", "label")


@dataclasses.dataclass(frozen=True)
class Selection:
    """A parsed selection: ``kind`` in :data:`KINDS`, its values, and the original text."""

    kind: str
    values: tuple[str, ...]
    text: str


def parse_selection(text: str) -> Selection:
    """Parse ``operator:a,b``, ``episodes:1,2,5-8`` or ``label:col=value``."""
    kind, sep, rest = text.partition(":")
    kind = kind.strip().lower()
    if not sep or kind not in KINDS or not rest.strip():
        raise ElicitError(
            f"bad selection '{text}': use operator:NAME[,NAME], episodes:ID[,ID] (ranges like "
            "0-4) or label:COLUMN=VALUE"
        )
    if kind == "label":
        col, eq, val = rest.partition("=")
        if not eq or not col.strip():
            raise ElicitError(f"bad selection '{text}': label needs COLUMN=VALUE")
        return Selection(kind, (col.strip(), val.strip()), text)
    if kind == "episodes":
        try:
            ids = parse_episode_ids(rest)
        except ElicitError as e:
            raise ElicitError(
                f"bad selection '{text}': episode ids must be integers or ranges like 0-4"
            ) from e
        return Selection(kind, tuple(str(i) for i in ids), text)
    values = tuple(v.strip() for v in rest.split(",") if v.strip())
    return Selection(kind, values, text)


def id_ranges(ids: list[int]) -> str:
    """Sorted ids as ranges, the way selections are written: ``[0, 1, 2, 5]`` -> ``0-2,5``."""
    parts: list[str] = []
    for i in sorted(ids):
        if parts and i == int(parts[-1].split("-")[-1]) + 1:
            parts[-1] = f"{parts[-1].split('-')[0]}-{i}"
        else:
            parts.append(str(i))
    return ",".join(parts)


def select_episodes(sel: Selection, columns: Mapping[str, np.ndarray]) -> np.ndarray:
    """Sorted episode ids of the pairs' ``columns`` matching ``sel``; errors when none match.

    Args:
      sel: a parsed selection.
      columns: per-pair columns with ``episode``, ``operator`` and any label columns.
    """
    episode = np.asarray(columns["episode"], np.int64)
    if sel.kind == "operator":
        match = np.isin(np.asarray(columns["operator"]).astype(str), list(sel.values))
        ids = np.unique(episode[match])
    elif sel.kind == "episodes":
        wanted = np.array([int(v) for v in sel.values], np.int64)
        missing = sorted(set(wanted.tolist()) - set(np.unique(episode).tolist()))
        if missing:
            have = np.unique(episode)
            raise ElicitError(
                f"selection '{sel.text}': no episode(s) {id_ranges(missing)} in the scores "
                f"(they hold {id_ranges(have.tolist())})"
            )
        ids = np.unique(wanted)
    else:
        col, value = sel.values
        if col not in columns:
            have = ", ".join(k for k in columns if k not in ("prediction",))
            raise ElicitError(f"selection '{sel.text}': no column '{col}' (have: {have})")
        text = np.char.lower(np.asarray(columns[col]).astype(str))
        hit = text == value.lower()
        ids_all, index = np.unique(episode, return_inverse=True)
        all_hit = np.bincount(index, weights=~hit, minlength=len(ids_all)) == 0
        ids = ids_all[all_hit]
    if not len(ids):
        ops = sorted({str(o) for o in np.asarray(columns["operator"]).tolist()})
        raise ElicitError(
            f"selection '{sel.text}' matches no episode in the scores (operators: {', '.join(ops)})"
        )
    return ids
