"""The record an ``elicit-jax export`` keeps in a LeRobot folder's ``artifact.json``.

LeRobot's format has no place for operators, observation-field slices or declared action
bounds. An export writes them next to its provenance (:func:`export_record`: ``episodes``
with each new episode's length and operator, and, for a dataset written from demonstrations,
``demos`` with obs fields, bounds and task); ``elicit-jax import`` reads them back
(:func:`read_record`) as long as the folder's episodes still have the recorded lengths.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from elicit_jax.artifact import read_json
from elicit_jax.data.demos import SOURCE_EPISODE, Demos, DemosWarning, ObsField

OBS_FEATURE = "observation.state"


def export_record(demos: Demos) -> dict[str, Any]:
    """What ``artifact.json`` keeps of the demos for a later import: per-episode operators and
    outcomes, obs fields, action bounds, task."""
    bounds = demos.episode_bounds()
    names = demos.extra.get(SOURCE_EPISODE)
    return {
        "episodes": [
            {
                "episode_index": i,
                "length": e - s,
                "operator": str(demos.operator[s]),
                "success": bool(demos.success[s]),
                "episode": ep,
                **({"source_episode": str(names[s])} if names is not None else {}),
            }
            for i, (ep, s, e) in enumerate(bounds)
        ],
        "demos": {
            "obs_feature": OBS_FEATURE,
            "obs_fields": {f.name: [f.start, f.stop] for f in demos.obs_fields}
            or {OBS_FEATURE: [0, demos.obs_dim]},
            "action_low": demos.action_low,
            "action_high": demos.action_high,
            "task": demos.task,
        },
    }


def read_record(
    root: Path, rows: Sequence[dict[str, Any]], obs_keys: Sequence[str]
) -> dict[str, Any] | None:
    """What an elicit-jax export recorded in ``artifact.json`` about the chosen episodes.

    Returns ``operators`` (episode index -> name) and, when the folder was written from
    demonstrations and ``obs_keys`` is its one observation feature, ``obs_fields``,
    ``action_low`` and ``action_high``; ``None`` (with a warning when the record no longer
    matches the episodes) if there is no such record.
    """
    path = root / "artifact.json"
    header = read_json(path) if path.is_file() else None
    if not isinstance(header, dict) or header.get("kind") != "export" or "episodes" not in header:
        return None
    listed = {int(e["episode_index"]): e for e in header["episodes"]}
    stale = [
        r for r in rows if listed.get(int(r["episode_index"]), {}).get("length") != r["length"]
    ]
    if stale:
        warnings.warn(
            f"{path}: does not describe episode {stale[0]['episode_index']} as it is now "
            "(changed after the export?); operators not restored",
            DemosWarning,
            stacklevel=3,
        )
        return None
    out: dict[str, Any] = {
        "operators": {e: str(listed[e].get("operator", "unknown")) for e in listed}
    }
    demos = header.get("demos") or {}
    if tuple(obs_keys) == (demos.get("obs_feature"),):
        out["obs_fields"] = tuple(
            ObsField(str(n), int(a), int(b))
            for n, (a, b) in sorted(demos["obs_fields"].items(), key=lambda kv: kv[1][0])
        )
        out["action_low"], out["action_high"] = demos["action_low"], demos["action_high"]
    return out
