"""Which episode of a LeRobot folder each entry of an elicit-jax export record describes.

LeRobot renumbers episodes when it edits a folder in place (``delete_episodes`` writes the
kept ones as 0..k-1) and appends after the last one (``resume()``), so an episode's index
says nothing about which recorded episode it is. An export records each episode's content
hash (:func:`elicit_jax.data.demos.episode_digest` of its frames as ``import`` reads them,
over the observation features named by ``sha256_of``); an episode takes the labels of the
recorded entry with its hash (its own index first, when several share it). Episodes no entry
matches (appended, or changed since) are labelled ``unknown``, with a warning.

A record written before the hashes (no ``sha256`` in its entries) can only be matched by
index and length: it is used if the folder still holds every episode it lists, each with its
recorded length (episodes appended after them are labelled ``unknown``), and refused
otherwise, since a deleted episode shifts every later index onto another episode's labels.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from elicit_jax.data.demos import DemosWarning
from elicit_jax.errors import ElicitError

Digests = Callable[[Sequence[str]], Mapping[int, str]]


def match_entries(
    where: Path,
    entries: Sequence[dict[str, Any]],
    record: Mapping[str, Any],
    rows: Sequence[dict[str, Any]],
    all_rows: Sequence[dict[str, Any]],
    obs_keys: Sequence[str],
    digests: Digests,
) -> dict[int, dict[str, Any]]:
    """Episode index -> the record entry describing it, for the chosen ``rows``.

    Args:
      where: the record's file (for messages).
      entries: the record's per-episode entries.
      record: the whole record (``sha256_of``: the obs features the hashes cover).
      rows: metadata rows of the episodes being imported.
      all_rows: metadata rows of every episode in the folder.
      obs_keys: the observation features being imported.
      digests: obs features -> episode index -> content hash of each chosen episode.
    """
    if entries and all("sha256" in e for e in entries):
        keys = (record.get("sha256_of") or {}).get("obs") or list(obs_keys)
        found = digests([str(k) for k in keys])
        matched = _by_hash(entries, rows, found)
        unmatched = [
            int(r["episode_index"]) for r in rows if int(r["episode_index"]) not in matched
        ]
        if unmatched:
            warnings.warn(
                f"{where}: {len(unmatched)} episodes ({_ids(unmatched)}) match no episode it "
                "records (their frames are not any exported episode's: appended after the "
                "export by LeRobot's resume(), or changed): labelled 'unknown' (`demos select "
                "--operator unknown` picks them out); the other episodes keep theirs, matched "
                "by content",
                DemosWarning,
                stacklevel=5,
            )
        return matched
    return _by_index(where, entries, rows, all_rows)


def _by_hash(
    entries: Sequence[dict[str, Any]], rows: Sequence[dict[str, Any]], found: Mapping[int, str]
) -> dict[int, dict[str, Any]]:
    by_hash: dict[str, list[dict[str, Any]]] = {}
    for e in entries:
        by_hash.setdefault(str(e["sha256"]), []).append(e)
    used: set[int] = set()
    matched: dict[int, dict[str, Any]] = {}
    for r in rows:
        i = int(r["episode_index"])
        free = [e for e in by_hash.get(found[i], []) if id(e) not in used]
        if not free:
            continue
        same = [e for e in free if int(e["episode_index"]) == i]
        entry = (same or free)[0]  # identical frames: any of them names this content
        used.add(id(entry))
        matched[i] = entry
    return matched


def _by_index(
    where: Path,
    entries: Sequence[dict[str, Any]],
    rows: Sequence[dict[str, Any]],
    all_rows: Sequence[dict[str, Any]],
) -> dict[int, dict[str, Any]]:
    lengths = {int(r["episode_index"]): int(r["length"]) for r in all_rows}
    for e in entries:
        i = int(e["episode_index"])
        if lengths.get(i) != int(e["length"]):
            now = "is gone" if i not in lengths else f"has {lengths[i]} frames"
            raise ElicitError(
                f"records episode {i} with {e['length']} frames, the folder's episode {i} {now}, "
                "and this record (from an older elicit-jax) has no content hashes to match "
                "episodes by: its labels would land on the wrong episodes; export the folder "
                "again, or move the record away to import without its labels",
                where,
            )
    listed = {int(e["episode_index"]): e for e in entries}
    new = [int(r["episode_index"]) for r in rows if int(r["episode_index"]) not in listed]
    if new:
        warnings.warn(
            f"{where}: {len(new)} episodes ({_ids(new)}) were added after the export (LeRobot's "
            "resume()?) and carry no operator label: labelled 'unknown' (`demos select "
            "--operator unknown` picks them out); the other episodes keep theirs",
            DemosWarning,
            stacklevel=5,
        )
    return {
        int(r["episode_index"]): listed[i] for r in rows if (i := int(r["episode_index"])) in listed
    }


def _ids(ids: list[int]) -> str:
    return ", ".join(map(str, ids[:5])) + (", ..." if len(ids) > 5 else "")
