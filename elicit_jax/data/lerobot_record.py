"""The record an ``elicit-jax export`` keeps in a LeRobot folder's ``artifact.json``.

LeRobot's format has no place for operators, observation-field slices, declared action
bounds, robomimic's ``env_args`` or the episodes' names in the dataset they were first
imported from; ``meta/info.json`` is no place either (LeRobot 0.6 drops keys it does not
know when it rewrites the file, e.g. on ``resume()``). An export writes them next to its
provenance (:func:`export_record`): ``episodes`` with each new episode's length, operator and
``source_episode`` name; for a dataset written from demonstrations, ``demos`` with obs fields,
bounds, task and ``env_args``; and ``origin``, the provenance of the dataset those names
belong to (a robomimic file: its path, content hashes, obs keys). ``elicit-jax import`` reads
them back (:func:`read_record`) for every episode that still has its recorded length;
episodes appended later (LeRobot's ``resume()``) are labelled ``unknown``, with a warning.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from elicit_jax.artifact import read_json
from elicit_jax.data.demos import SOURCE_EPISODE, Demos, DemosWarning, ObsField
from elicit_jax.data.selection import recorded_env_args, single_source
from elicit_jax.errors import ElicitError

OBS_FEATURE = "observation.state"


def _origin(demos: Demos) -> dict[str, Any] | None:
    """Provenance of the one dataset the demos' ``source_episode`` names belong to."""
    names = demos.extra.get(SOURCE_EPISODE)
    if names is None:
        return None
    try:
        prov = single_source(demos.provenance, "<demos>")
    except ElicitError:
        return None
    origin = dict(prov.get("origin") or prov)  # names restored from an earlier record
    origin.pop("episode_index", None)
    listed = {str(n) for n in names}
    if isinstance(origin.get("episode_sha256"), dict):
        origin["episode_sha256"] = {
            k: v for k, v in origin["episode_sha256"].items() if k in listed
        }
    return origin


def export_record(demos: Demos) -> dict[str, Any]:
    """What ``artifact.json`` keeps of the demos for a later import: per-episode operators,
    outcomes and source names, obs fields, action bounds, task, ``env_args`` and ``origin``."""
    bounds = demos.episode_bounds()
    names = demos.extra.get(SOURCE_EPISODE)
    env = recorded_env_args(demos.provenance)
    origin = _origin(demos)
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
            **({"env_args": env} if env is not None else {}),
        },
        **({"origin": origin} if origin is not None else {}),
    }


def carried_record(root: Path) -> dict[str, Any]:
    """The parts of a folder's record that a selection of its episodes keeps as they are
    (``demos``: features, bounds, ``env_args``; ``origin``)."""
    path = root / "artifact.json"
    header = read_json(path) if path.is_file() else None
    if not isinstance(header, dict) or header.get("kind") != "export":
        return {}
    return {k: header[k] for k in ("demos", "origin") if isinstance(header.get(k), dict)}


def read_record(
    root: Path, rows: Sequence[dict[str, Any]], obs_keys: Sequence[str]
) -> dict[str, Any] | None:
    """What an elicit-jax export recorded in ``artifact.json`` about the chosen episodes.

    Returns ``None`` if there is no such record, else ``operators`` (episode index -> name,
    ``unknown`` for an episode the record does not describe as it is now, e.g. one appended
    by LeRobot's ``resume()``; each such case is warned about), ``names`` (episode index ->
    recorded ``source_episode``, for the described episodes), ``unlabelled`` (the episode
    indices it does not describe), ``origin`` and ``env_args``
    when recorded, and, when the folder was written from demonstrations and ``obs_keys`` is
    its one observation feature, ``obs_fields``, ``action_low`` and ``action_high``.
    """
    path = root / "artifact.json"
    header = read_json(path) if path.is_file() else None
    if not isinstance(header, dict) or header.get("kind") != "export" or "episodes" not in header:
        return None
    try:
        return _parse_record(path, header, rows, obs_keys)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as e:
        raise ElicitError(f"malformed export record ({type(e).__name__}: {e})", path) from e


def _parse_record(
    path: Path, header: dict[str, Any], rows: Sequence[dict[str, Any]], obs_keys: Sequence[str]
) -> dict[str, Any]:
    listed = {int(e["episode_index"]): e for e in header["episodes"]}
    described = {
        int(r["episode_index"]): listed[int(r["episode_index"])]
        for r in rows
        if listed.get(int(r["episode_index"]), {}).get("length") == r["length"]
    }
    _warn_undescribed(path, rows, listed, described)
    out: dict[str, Any] = {
        "operators": {
            int(r["episode_index"]): str(
                described.get(int(r["episode_index"]), {}).get("operator", "unknown")
            )
            for r in rows
        },
        "names": {
            e: str(d["source_episode"]) for e, d in described.items() if "source_episode" in d
        },
        "unlabelled": [
            int(r["episode_index"]) for r in rows if int(r["episode_index"]) not in described
        ],
    }
    if isinstance(header.get("origin"), dict):
        out["origin"] = header["origin"]
    demos = header.get("demos") or {}
    if isinstance(demos.get("env_args"), dict):
        out["env_args"] = demos["env_args"]
    if tuple(obs_keys) == (demos.get("obs_feature"),):
        out["obs_fields"] = tuple(
            ObsField(str(n), int(a), int(b))
            for n, (a, b) in sorted(demos["obs_fields"].items(), key=lambda kv: kv[1][0])
        )
        out["action_low"], out["action_high"] = demos["action_low"], demos["action_high"]
    return out


def _warn_undescribed(
    path: Path,
    rows: Sequence[dict[str, Any]],
    listed: dict[int, dict[str, Any]],
    described: dict[int, dict[str, Any]],
) -> None:
    new = [int(r["episode_index"]) for r in rows if int(r["episode_index"]) not in listed]
    changed = [
        int(r["episode_index"])
        for r in rows
        if int(r["episode_index"]) in listed and int(r["episode_index"]) not in described
    ]
    if new:
        warnings.warn(
            f"{path}: {len(new)} episodes ({_ids(new)}) were added after the export (LeRobot's "
            "resume()?) and carry no operator label: labelled 'unknown' (`demos select "
            "--operator unknown` picks them out); the other episodes keep theirs",
            DemosWarning,
            stacklevel=4,
        )
    if changed:
        warnings.warn(
            f"{path}: does not describe {len(changed)} episodes ({_ids(changed)}) as they are "
            "now (their length changed after the export): labelled 'unknown'",
            DemosWarning,
            stacklevel=4,
        )


def _ids(ids: list[int]) -> str:
    return ", ".join(map(str, ids[:5])) + (", ..." if len(ids) > 5 else "")


def restore_names(rows: Sequence[dict[str, Any]], labels: dict[str, Any] | None) -> dict[int, str]:
    """Episode index -> the episode's ``source_episode`` name: the name an export recorded in
    the dataset it names as ``origin`` (``demo_12``), else (no origin, an episode appended
    since, or names that would clash) the ``episode_index`` itself."""
    own = {int(r["episode_index"]): str(r["episode_index"]) for r in rows}
    if not labels or "origin" not in labels or not labels["names"]:
        return own
    names = {e: labels["names"].get(e, n) for e, n in own.items()}
    return names if len(set(names.values())) == len(names) else own


def lerobot_indices(names: Sequence[str], provenance: dict[str, Any], source: str) -> list[int]:
    """The ``episode_index`` of each named episode in the LeRobot folder the demos were
    imported from (names restored from an export's record map back through the import's
    ``provenance['episode_index']``)."""
    index = provenance.get("episode_index") or {}
    out = []
    for n in names:
        if n in index:
            out.append(int(index[n]))
        elif str(n).isdigit():
            out.append(int(n))
        else:
            raise ElicitError(f"has no episode {n!r} (LeRobot episodes are numbered)", source)
    return out


def restored_provenance(labels: dict[str, Any], names: dict[int, str]) -> dict[str, Any]:
    """Provenance an export's record gives back: ``env_args``, and, when the episodes carry
    names from their ``origin``, that origin and the name -> ``episode_index`` map."""
    out = {k: labels[k] for k in ("env_args", "origin") if k in labels}
    if labels.get("unlabelled"):  # episodes the record does not describe (appended since)
        out["unlabelled_episodes"] = labels["unlabelled"]
    if any(n != str(e) for e, n in names.items()):
        out["episode_index"] = {n: e for e, n in names.items()}
    else:
        out.pop("origin", None)  # the names are this folder's own
    return out
