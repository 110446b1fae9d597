"""Subsets and unions of demonstration artifacts: ``elicit-jax demos select`` / ``concat``.

``select`` keeps the episode ids of its input, so an id names the same demonstration in the
whole import and in every subset of it; the ``source_episode`` column (``demo_12`` for
robomimic, the ``episode_index`` for LeRobot) names it in the original dataset and survives
both operations, so exports still map back. ``concat`` renumbers episodes 0..E-1 in input
order (ids of different files would collide) and records which input each came from.

Example:
    >>> select_file("demos.parquet", "heldout.parquet", SubsetSpec(episodes="0-4"))
    >>> select_file("demos.parquet", "train.parquet", SubsetSpec(exclude="0-4"))
    >>> concat_files(["base.parquet", "op2.parquet"], "mixed.parquet")
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import refuse_overwriting_inputs
from elicit_jax.data.demo_set import SOURCE_EPISODE, Demos
from elicit_jax.data.demos import concat_demos, read_demos, write_demos
from elicit_jax.data.duplicates import describe, find_duplicates
from elicit_jax.data.selection import parse_episode_ids
from elicit_jax.errors import ElicitError

PART = "part"


@dataclasses.dataclass(frozen=True)
class SubsetSpec:
    """Which episodes to keep; every given criterion must hold (none given: all episodes).

    Attributes:
      episodes: episode ids and ranges to keep, e.g. ``"0-4,7"``.
      exclude: episode ids and ranges to drop.
      operators: operator names to keep, comma-separated.
      source_episodes: names in the source dataset to keep, e.g. ``"demo_3,demo_7"``.
      first: of the episodes the other criteria keep, only the first ``first`` (in id
        order); fewer than that is an error.
      drop_first: of the episodes the other criteria keep, all but the first ``drop_first``
        (with the same criteria, ``first=N`` and ``drop_first=N`` split them in two).
    """

    episodes: str | None = None
    exclude: str | None = None
    operators: str | None = None
    source_episodes: str | None = None
    first: int | None = None
    drop_first: int | None = None


def _names(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def episode_table(demos: Demos) -> list[dict[str, Any]]:
    """One row per episode: id, source episode, operator, steps, success."""
    names = demos.extra.get(SOURCE_EPISODE)
    return [
        {
            "episode": e,
            "source_episode": str(names[s]) if names is not None else "-",
            "operator": str(demos.operator[s]),
            "steps": stop - s,
            "success": bool(demos.success[s]),
        }
        for e, s, stop in demos.episode_bounds()
    ]


def select(demos: Demos, spec: SubsetSpec, source: str = "<demos>") -> Demos:
    """The episodes of ``demos`` matching ``spec``, ids unchanged.

    Raises:
      ElicitError: a listed id or source name the demos do not hold, or nothing selected.
    """
    table = episode_table(demos)
    ids = np.array([r["episode"] for r in table], np.int64)
    keep = np.ones(len(ids), bool)
    if spec.episodes is not None:
        wanted = parse_episode_ids(spec.episodes)
        missing = sorted(set(wanted) - set(ids.tolist()))
        if missing:
            raise ElicitError(
                f"has no episode {missing[0]} (ids {ids.min()}..{ids.max()}; "
                "see elicit-jax demos list)",
                source,
            )
        keep &= np.isin(ids, wanted)
    if spec.exclude is not None:
        keep &= ~np.isin(ids, parse_episode_ids(spec.exclude))
    if spec.operators is not None:
        ops = np.array([r["operator"] for r in table])
        unknown = sorted(set(_names(spec.operators)) - set(ops.tolist()))
        if unknown:
            have = ", ".join(sorted({str(o) for o in ops.tolist()}))
            raise ElicitError(f"has no operator '{unknown[0]}' (operators: {have})", source)
        keep &= np.isin(ops, _names(spec.operators))
    if spec.source_episodes is not None:
        if SOURCE_EPISODE not in demos.extra:
            raise ElicitError("has no source_episode column to select by", source)
        names = np.array([r["source_episode"] for r in table])
        wanted_names = _names(spec.source_episodes)
        unknown = sorted(set(wanted_names) - set(names.tolist()))
        if unknown:
            raise ElicitError(f"has no source episode '{unknown[0]}'", source)
        keep &= np.isin(names, wanted_names)
    chosen = np.sort(ids[keep])
    if spec.first is not None:
        if len(chosen) < spec.first:
            raise ElicitError(
                f"--first {spec.first}: the other criteria keep only {len(chosen)} episodes",
                source,
            )
        chosen = chosen[: spec.first]
    if spec.drop_first is not None:
        chosen = chosen[spec.drop_first :]
    if not len(chosen):
        raise ElicitError("the selection keeps no episode", source)
    return demos.select_episodes(chosen)


def select_file(path: str | Path, out: str | Path, spec: SubsetSpec) -> Demos:
    """Write the episodes of the demos file ``path`` matching ``spec`` to ``out``."""
    refuse_overwriting_inputs([out], [path])
    demos = read_demos(path)
    chosen = select(demos, spec, str(path))
    return write_demos(
        out,
        chosen,
        config={"select": dataclasses.asdict(spec)},
        inputs={"demos": path},
        bounds=_policy(path),
    )


def concat_files(
    paths: Sequence[str | Path], out: str | Path, *, allow_duplicates: bool = False
) -> Demos:
    """Concatenate demos files into ``out``; episodes renumbered 0..E-1 in input order.

    The extra column ``part`` holds each episode's input index; columns every input has
    (``source_episode``, ...) are kept. Inputs must agree on dimensions and observation fields.
    An episode identical to an earlier one (:mod:`elicit_jax.data.duplicates`) is refused
    unless ``allow_duplicates``; the header's ``config.duplicates_kept`` lists those kept.
    """
    if len(paths) < 2:
        raise ElicitError("concat needs at least two demos files")
    refuse_overwriting_inputs([out], paths)
    parts = [read_demos(p) for p in paths]
    first = [f.name for f in parts[0].obs_fields]
    for p, d in zip(paths[1:], parts[1:], strict=True):
        names = [f.name for f in d.obs_fields]
        if names != first:
            raise ElicitError(f"has obs fields {names}, the first file {first}", p)
    tagged = [
        dataclasses.replace(d, extra={**d.extra, PART: np.full(d.n_steps, i, np.int64)})
        for i, d in enumerate(parts)
    ]
    dropped = sorted(
        set().union(*(d.extra for d in parts)) - set.intersection(*(set(d.extra) for d in parts))
    )
    dups = find_duplicates(parts)
    if dups and not allow_duplicates:
        raise ElicitError(
            f"{len(dups)} episode(s) repeat earlier ones: "
            f"{describe(dups, [str(p) for p in paths])}; pass --allow-duplicates to keep them",
            out,
        )
    joined = concat_demos(tagged, renumber=True)
    return write_demos(
        out,
        joined,
        config={
            "concat": [str(p) for p in paths],
            "columns_dropped": dropped,
            "duplicates_kept": [dataclasses.asdict(d) for d in dups],
        },
        inputs={f"demos{i}": p for i, p in enumerate(paths)},
        bounds=_policy(paths[0]),
    )


def _policy(path: str | Path) -> Any:
    """The action-bounds policy the file was written with (kept by its subsets)."""
    from elicit_jax.artifact import read_header

    return read_header(path).get("action_bounds_policy", "error")
