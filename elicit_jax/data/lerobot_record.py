"""The record an ``elicit-jax export`` keeps of a LeRobot folder's episodes.

LeRobot's format has no place for operators, observation-field slices, declared action
bounds, robomimic's ``env_args``, the episodes' names in the dataset they were first
imported from, or elicit-jax's own per-step columns (``pre_filter_episode``,
``pre_filter_step``, ``part``, ``subset``: kept out of LeRobot's features, so that a user's
own ``add_frame`` after ``resume()`` does not need them). An export writes them
(:func:`export_record`): ``episodes`` with each new episode's length, content hash
(``sha256``, over the features named by ``sha256_of``), operator, ``source_episode`` name
and own columns; for a dataset written from demonstrations, ``demos`` with obs fields,
bounds, task and ``env_args``; and ``origin``, the provenance of the dataset those names
belong to (a robomimic file: its path, content hashes, obs keys).

The record goes twice into the folder: in ``artifact.json`` beside the export's provenance,
and under the ``elicit_jax`` key of ``meta/info.json``, which LeRobot's v2.1 -> v3.0
converter carries into the folder it writes (``artifact.json`` stays behind in ``*_old/``).
LeRobot 0.6 drops keys it does not know when it rewrites ``info.json`` (``resume()``), but
leaves ``artifact.json`` in place. ``elicit-jax import`` reads ``artifact.json``, else the
``info.json`` copy (:func:`read_record`), and matches entries to episodes by content
(:mod:`.lerobot_match`); with neither but a ``*_old/artifact.json`` beside the folder, it
says so.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import read_json
from elicit_jax.data.demos import SOURCE_EPISODE, Demos, DemosWarning, ObsField, episode_digest
from elicit_jax.data.lerobot_match import Digests, match_entries
from elicit_jax.data.selection import recorded_env_args, single_source
from elicit_jax.errors import ElicitError

OBS_FEATURE = "observation.state"
INFO_KEY = "elicit_jax"  # the record's copy in meta/info.json
# elicit-jax's own per-step columns: kept in the record, never LeRobot features
OWN_COLUMNS = ("pre_filter_episode", "pre_filter_step", "part", "subset")
RECORD_KEYS = ("episodes", "sha256_of", "columns", "demos", "origin")


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


def encode_column(values: np.ndarray) -> Any:
    """One episode's values of an own column, compactly: a constant, ``{"from": first}`` for
    consecutive integers, else the list."""
    values = np.asarray(values)
    if values.dtype.kind in "iub":
        ints = values.astype(np.int64)
        if (ints == ints[0]).all():
            return int(ints[0])
        if np.array_equal(ints, ints[0] + np.arange(len(ints))):
            return {"from": int(ints[0])}
        return ints.tolist()
    texts = [str(v) for v in values]
    return texts[0] if len(set(texts)) == 1 else texts


def decode_column(value: Any, dtype: str, length: int) -> np.ndarray:
    """The inverse of :func:`encode_column` (a one-line error if it does not fit)."""
    kind = np.dtype(dtype) if dtype != "object" else np.dtype(object)
    if isinstance(value, dict):
        out = int(value["from"]) + np.arange(length)
    elif isinstance(value, list):
        if len(value) != length:
            raise ValueError(f"column values list {len(value)} steps for {length}")
        out = np.asarray(value)
    else:
        out = np.full(length, value)
    return out.astype(kind)


def _own_columns(demos: Demos) -> dict[str, str]:
    return {
        k: np.asarray(demos.extra[k]).dtype.name
        for k in OWN_COLUMNS
        if k in demos.extra and np.asarray(demos.extra[k]).ndim == 1
    }


def export_record(demos: Demos) -> dict[str, Any]:
    """What the folder keeps of the demos for a later import: per-episode content hashes,
    operators, outcomes, source names and own columns, obs fields, action bounds, task,
    ``env_args`` and ``origin``."""
    bounds = demos.episode_bounds()
    names = demos.extra.get(SOURCE_EPISODE)
    env = recorded_env_args(demos.provenance)
    origin = _origin(demos)
    columns = _own_columns(demos)
    return {
        "episodes": [
            {
                "episode_index": i,
                "length": e - s,
                "sha256": episode_digest(demos.obs[s:e], demos.action[s:e], demos.reward[s:e]),
                "operator": str(demos.operator[s]),
                "success": bool(demos.success[s]),
                "episode": ep,
                **({"source_episode": str(names[s])} if names is not None else {}),
                **(
                    {"columns": {k: encode_column(demos.extra[k][s:e]) for k in columns}}
                    if columns
                    else {}
                ),
            }
            for i, (ep, s, e) in enumerate(bounds)
        ],
        "sha256_of": {"obs": [OBS_FEATURE], "reward": "next.reward"},
        **({"columns": columns} if columns else {}),
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


def info_record(header: dict[str, Any]) -> dict[str, Any]:
    """The record's parts of an export header: the copy kept in ``meta/info.json``."""
    return {"kind": "export", **{k: header[k] for k in RECORD_KEYS if k in header}}


def carried_record(root: Path) -> dict[str, Any]:
    """The parts of a folder's record that a selection of its episodes keeps as they are
    (``demos``: features, bounds, ``env_args``; ``origin``)."""
    header = _find_record(root, _read_info(root))[0]
    if header is None:
        return {}
    return {k: header[k] for k in ("demos", "origin") if isinstance(header.get(k), dict)}


def _read_info(root: Path) -> dict[str, Any]:
    path = root / "meta" / "info.json"
    info = read_json(path) if path.is_file() else None
    return info if isinstance(info, dict) else {}


def _find_record(root: Path, info: dict[str, Any]) -> tuple[dict[str, Any] | None, Path]:
    """The folder's record and where it was read: ``artifact.json``, else ``info.json``'s."""
    path = root / "artifact.json"
    header = read_json(path) if path.is_file() else None
    if isinstance(header, dict) and header.get("kind") == "export" and "episodes" in header:
        return header, path
    kept = info.get(INFO_KEY)
    if isinstance(kept, dict) and "episodes" in kept:
        return kept, root / "meta" / "info.json"
    return None, path


def read_record(
    root: Path,
    info: dict[str, Any],
    rows: Sequence[dict[str, Any]],
    all_rows: Sequence[dict[str, Any]],
    obs_keys: Sequence[str],
    digests: Digests,
) -> dict[str, Any] | None:
    """What an elicit-jax export recorded about the chosen episodes.

    Args:
      root: the dataset folder.
      info: its ``meta/info.json``.
      rows: metadata rows of the chosen episodes; ``all_rows``: of every episode.
      obs_keys: the observation features being imported.
      digests: obs features -> episode index -> content hash (see :mod:`.lerobot_match`).

    Returns:
      ``None`` if there is no record (warned about when LeRobot's converter left one in
      ``<folder>_old/``), else ``from`` (where it was read), ``operators`` (episode index ->
      name, ``unknown`` for an episode no entry matches, each such case warned about),
      ``names`` (episode index -> recorded ``source_episode``, for the matched episodes),
      ``unlabelled`` (the episode indices it does not describe), ``columns`` (own column ->
      dtype) and ``column_values`` (episode index -> own column -> encoded values) when
      recorded, ``origin`` and ``env_args`` when recorded, and, when the folder was written
      from demonstrations and ``obs_keys`` is its one observation feature, ``obs_fields``,
      ``action_low`` and ``action_high``.
    """
    header, where = _find_record(root, info)
    if header is None:
        _warn_left_behind(root)
        return None
    try:
        return _parse_record(where, header, rows, all_rows, obs_keys, digests)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as e:
        raise ElicitError(f"malformed export record ({type(e).__name__}: {e})", where) from e


def _warn_left_behind(root: Path) -> None:
    old = root.parent / f"{root.name}_old" / "artifact.json"
    header = read_json(old) if old.is_file() else None
    if isinstance(header, dict) and header.get("kind") == "export":
        warnings.warn(
            f"{root}: holds no elicit-jax export record, but {old} does (LeRobot's v2.1 -> "
            "v3.0 converter moves the old folder there): every episode is labelled "
            "'unknown', named by its index, without env_args; copy that artifact.json into "
            f"{root} and import again to get its operators and demo names back",
            DemosWarning,
            stacklevel=4,
        )


def _parse_record(
    where: Path,
    header: dict[str, Any],
    rows: Sequence[dict[str, Any]],
    all_rows: Sequence[dict[str, Any]],
    obs_keys: Sequence[str],
    digests: Digests,
) -> dict[str, Any]:
    matched = match_entries(where, header["episodes"], header, rows, all_rows, obs_keys, digests)
    out: dict[str, Any] = {
        "from": ("meta/info.json" if where.name == "info.json" else where.name)
        + " (elicit-jax export)",
        "operators": {
            int(r["episode_index"]): str(
                matched.get(int(r["episode_index"]), {}).get("operator", "unknown")
            )
            for r in rows
        },
        "names": {e: str(d["source_episode"]) for e, d in matched.items() if "source_episode" in d},
        "unlabelled": [
            int(r["episode_index"]) for r in rows if int(r["episode_index"]) not in matched
        ],
    }
    if isinstance(header.get("columns"), dict):
        out["columns"] = {str(k): str(v) for k, v in header["columns"].items()}
        out["column_values"] = {e: dict(d.get("columns") or {}) for e, d in matched.items()}
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


def episode_digests(
    rows: Sequence[dict[str, Any]], eps: Sequence[dict[str, np.ndarray]]
) -> dict[int, str]:
    """Episode index -> content hash of its frames as read."""
    return {
        int(r["episode_index"]): episode_digest(ep["obs"], ep["action"], ep.get("reward"))
        for r, ep in zip(rows, eps, strict=True)
    }


def label_episodes(
    root: Path,
    info: dict[str, Any],
    rows: Sequence[dict[str, Any]],
    all_rows: Sequence[dict[str, Any]],
    obs_keys: Sequence[str],
    eps: Sequence[dict[str, np.ndarray]],
    reread: Callable[[Sequence[str]], Sequence[dict[str, np.ndarray]]],
) -> tuple[dict[str, Any] | None, dict[int, str], dict[str, str]]:
    """Give the episodes just read (``eps``, for ``rows``) what the folder's record says of
    them: each its ``source_episode`` name and own columns, matched by content.

    Args:
      root, info, rows, all_rows, obs_keys: as for :func:`read_record`.
      eps: the episodes' frames (``obs``, ``action``, ``reward``), completed in place.
      reread: obs features -> the episodes read with those as ``obs`` (for a record whose
        hashes cover other features than ``obs_keys``).

    Returns:
      ``(labels, names, digests)``: :func:`read_record`'s answer, each episode's name by its
      index and its content hash by its name.
    """
    own = episode_digests(rows, eps)

    def digests(keys: Sequence[str]) -> Mapping[int, str]:
        return own if tuple(keys) == tuple(obs_keys) else episode_digests(rows, reread(keys))

    labels = read_record(root, info, rows, all_rows, obs_keys, digests)
    names = restore_names(rows, labels)
    columns = restore_columns(labels, rows)
    for r, ep in zip(rows, eps, strict=True):
        e = int(r["episode_index"])
        ep[SOURCE_EPISODE] = np.full(len(ep["obs"]), names[e], dtype=object)
        ep.update(columns[e])
    return labels, names, {names[e]: d for e, d in own.items()}


def restore_columns(
    labels: dict[str, Any] | None, rows: Sequence[dict[str, Any]]
) -> dict[int, dict[str, np.ndarray]]:
    """Episode index -> own column -> per-step values, for columns every chosen episode has
    in the record (none otherwise: a column only some episodes have is dropped)."""
    if not labels or not labels.get("columns"):
        return {int(r["episode_index"]): {} for r in rows}
    values = labels["column_values"]
    keep = [
        k
        for k in labels["columns"]
        if all(k in values.get(int(r["episode_index"]), {}) for r in rows)
    ]
    try:
        return {
            int(r["episode_index"]): {
                k: decode_column(
                    values[int(r["episode_index"])][k], labels["columns"][k], int(r["length"])
                )
                for k in keep
            }
            for r in rows
        }
    except (KeyError, TypeError, ValueError) as e:
        raise ElicitError(f"malformed own column in the export record ({e})") from e


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
