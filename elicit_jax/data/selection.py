"""Episode selections: which episodes of a source dataset to export.

A selection comes from a demonstrations artifact (its episodes, optionally narrowed by an
explicit id list) or from an ``episode-list`` JSON artifact written by ``elicit-jax export``.
Each selected episode carries its name in the source dataset (``demo_12`` for robomimic, the
``episode_index`` for LeRobot), taken from the demos' ``source_episode`` column, so exports
map back to the original file.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import make_header, read_artifact, read_header, write_json
from elicit_jax.data.demos import SOURCE_EPISODE, Demos, read_demos
from elicit_jax.errors import ElicitError

EPISODE_LIST_KIND = "episode-list"
EPISODE_LIST_SCHEMA_VERSION = 1


@dataclasses.dataclass(frozen=True)
class Selection:
    """Selected episodes and where they came from.

    Attributes:
      episodes: episode ids in the demonstrations artifact, in row order.
      source_episodes: the same episodes' names in the source dataset.
      operators: operator of each selected episode.
      provenance: the demonstrations' provenance (source path, sha256, importer, ...).
      lengths: steps of each selected episode in the demonstrations (``None`` for an
        episode list, which holds no steps).
    """

    episodes: tuple[int, ...]
    source_episodes: tuple[str, ...]
    operators: tuple[str, ...]
    provenance: Mapping[str, Any]
    lengths: tuple[int, ...] | None = None


def parse_episode_ids(text: str) -> list[int]:
    """Parse ``"0,3,5"`` or ranges ``"0-4,7"`` into a sorted list of unique ids."""
    out: set[int] = set()
    for part in (p.strip() for p in text.split(",")):
        m = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if not m:
            raise ElicitError(f"bad episode list {text!r}: use ids and ranges like 0,3,5-8")
        a, b = int(m[1]), int(m[2] or m[1])
        if b < a:
            raise ElicitError(f"bad episode range {part!r} in {text!r}")
        out.update(range(a, b + 1))
    return sorted(out)


def selection_from_demos(
    demos: Demos, episodes: Sequence[int] | None = None, source: str = "<demos>"
) -> Selection:
    """The episodes of ``demos`` (all, or those with the given ids) as a :class:`Selection`."""
    bounds = demos.episode_bounds()
    have = {e for e, _, _ in bounds}
    if episodes is not None:
        missing = sorted(set(episodes) - have)
        if missing:
            raise ElicitError(f"has no episode {missing[0]} (ids {min(have)}..{max(have)})", source)
        bounds = [b for b in bounds if b[0] in set(episodes)]
    if not bounds:
        raise ElicitError("no episodes selected", source)
    names = demos.extra.get(SOURCE_EPISODE)
    return Selection(
        episodes=tuple(e for e, _, _ in bounds),
        source_episodes=tuple(str(names[s]) if names is not None else str(e) for e, s, _ in bounds),
        operators=tuple(str(demos.operator[s]) for _, s, _ in bounds),
        provenance=dict(demos.provenance),
        lengths=tuple(e - s for _, s, e in bounds),
    )


def read_selection(path: str | Path, episodes: Sequence[int] | None = None) -> Selection:
    """A selection from a demos artifact or an episode-list JSON, optionally narrowed."""
    if read_header(path).get("kind") == "demos":
        return selection_from_demos(read_demos(path, bounds="warn"), episodes, str(path))
    what = "demos or an episode list"
    header = read_artifact(path, EPISODE_LIST_KIND, EPISODE_LIST_SCHEMA_VERSION, what=what)
    try:
        ids = [int(x) for x in header["episodes"]]
        names = [str(x) for x in header["source_episodes"]]
        ops = [str(x) for x in header.get("operators", ["unknown"] * len(ids))]
    except (KeyError, TypeError, ValueError) as e:
        raise ElicitError(f"malformed episode list ({e})", path) from e
    if not len(ids) == len(names) == len(ops):
        raise ElicitError(
            "episode list: episodes, source_episodes, operators differ in length", path
        )
    keep = np.ones(len(ids), bool) if episodes is None else np.isin(ids, list(episodes))
    if episodes is not None and sorted(set(episodes) - set(ids)):
        raise ElicitError(f"lists no episode {sorted(set(episodes) - set(ids))[0]}", path)
    if not keep.any():
        raise ElicitError("no episodes selected", path)
    return Selection(
        episodes=tuple(i for i, k in zip(ids, keep, strict=True) if k),
        source_episodes=tuple(n for n, k in zip(names, keep, strict=True) if k),
        operators=tuple(o for o, k in zip(ops, keep, strict=True) if k),
        provenance=dict(header.get("source", {})),
    )


def write_episode_list(
    path: str | Path,
    selection: Selection,
    *,
    config: Mapping[str, Any] | None = None,
    inputs: Mapping[str, str | Path] | None = None,
) -> None:
    """Atomically write ``selection`` as an ``episode-list`` JSON artifact.

    ``source_episodes`` are written as integers when they all are (LeRobot's
    ``episode_index``), so ``LeRobotDataset(..., episodes=...)`` takes the list as it is.
    """
    names = list(selection.source_episodes)
    if all(re.fullmatch(r"\d+", n) for n in names):
        names = [int(n) for n in names]
    header = make_header(
        EPISODE_LIST_KIND,
        EPISODE_LIST_SCHEMA_VERSION,
        config=config,
        inputs=inputs,
        episodes=list(selection.episodes),
        source_episodes=names,
        operators=list(selection.operators),
        n_episodes=len(selection.episodes),
        source=dict(selection.provenance),
    )
    write_json(path, header)


def provenance_leaves(provenance: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    """The provenance of each imported (or collected) part of concatenated demonstrations."""
    parts = provenance.get("parts")
    if not parts:
        return [provenance]
    return [leaf for p in parts for leaf in provenance_leaves(p)]


def single_source(provenance: Mapping[str, Any], path: str | Path) -> dict[str, Any]:
    """The one dataset the demonstrations were imported from.

    Demos concatenated from several imports of the same file (``filter --base``, ``demos
    concat``) count as one source: their per-episode content hashes are merged.

    Raises:
      ElicitError: the demos were not imported, or come from several datasets.
    """
    leaves = provenance_leaves(provenance)
    sources = sorted({(str(p.get("importer")), str(p.get("source"))) for p in leaves})
    if any(not p.get("importer") for p in leaves):
        raise ElicitError(
            f"holds demonstrations that were not imported from a dataset "
            f"({leaves[0].get('source') or 'no recorded source'})",
            path,
        )
    if len(sources) > 1:
        raise ElicitError(
            f"holds demonstrations from {len(sources)} datasets "
            f"({', '.join(s for _, s in sources)})",
            path,
        )
    merged = dict(leaves[0])
    digests: dict[str, str] = {}
    for p in leaves:
        for name, h in (p.get("episode_sha256") or {}).items():
            if digests.setdefault(name, h) != h:
                raise ElicitError(
                    f"its parts were imported from different versions of {merged['source']} "
                    f"(episode {name} differs)",
                    path,
                )
    if all("episode_sha256" in p for p in leaves):
        merged["episode_sha256"] = digests
    else:
        merged.pop("episode_sha256", None)
    indices: dict[str, int] = {}
    for p in leaves:  # LeRobot imports that restored names: name -> episode_index
        indices.update(p.get("episode_index") or {})
    if indices:
        merged["episode_index"] = indices
    return merged


def recorded_env_args(provenance: Mapping[str, Any]) -> dict[str, Any] | None:
    """The robomimic ``env_args`` the demonstrations' sources recorded, if they agree on one.

    Found in a robomimic import's provenance, or in that of a LeRobot import whose folder an
    elicit-jax export wrote from robomimic demonstrations (it keeps them in ``artifact.json``).
    """
    import json

    found = {
        json.dumps(p["env_args"], sort_keys=True): p["env_args"]
        for p in provenance_leaves(provenance)
        if isinstance(p.get("env_args"), dict)
    }
    return next(iter(found.values())) if len(found) == 1 else None
