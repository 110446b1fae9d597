"""Plain NumPy archives (``.npz``) of demonstrations.

Keys read: ``obs`` (N, O), ``act`` or ``action`` (N, A), and episode boundaries as either
``lengths`` (E,) or ``episode_ids`` (N,) (each episode's rows contiguous). Optional:
``operators`` (E,) or (N,) strings, ``rewards`` (N,), ``success`` (E,) or (N,) booleans.
Export writes all of these plus ``source_episode`` (E,) and the demos header as JSON text
under ``elicit_jax_header``.
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import atomic_path, dumps
from elicit_jax.data.demos import (
    SOURCE_EPISODE,
    Demos,
    fields_from_sizes,
    from_episodes,
    make_provenance,
    validate,
)
from elicit_jax.errors import ElicitError

ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # a zip's first entry, or an empty zip's end


def load_arrays(path: str | Path) -> dict[str, np.ndarray]:
    """Every array of a ``.npz`` archive, with one-line errors naming the file.

    A file that is not a zip archive is refused as such (``numpy.load`` would call it
    "pickled data"); object arrays are refused, never unpickled.

    Raises:
      ElicitError: a folder, a missing file, not a .npz archive, an object array, a damaged
        archive.
    """
    path = Path(path)
    if path.is_dir():
        raise ElicitError("is a folder, not a .npz file", path)
    if not path.is_file():
        raise ElicitError("file not found", path)
    with open(path, "rb") as f:
        if f.read(4) not in ZIP_MAGIC:
            raise ElicitError(
                "not a .npz archive: a .npz is a zip file of .npy arrays, and this file is "
                "not a zip file",
                path,
            )
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except ValueError as e:
        if "allow_pickle" in str(e):
            raise ElicitError(
                "holds an object (pickled) array, which is never loaded: save plain numeric "
                "or string arrays",
                path,
            ) from e
        raise ElicitError(f"not a readable .npz archive ({e})", path) from e
    except (OSError, zipfile.BadZipFile, EOFError, KeyError) as e:
        raise ElicitError(f"damaged .npz archive ({type(e).__name__}: {e})", path) from e


def _boundaries(arrays: dict[str, np.ndarray], n: int, path: Path) -> list[tuple[int, int, Any]]:
    """``(start, stop, source_id)`` of each episode."""
    if "lengths" in arrays:
        lengths = np.asarray(arrays["lengths"]).reshape(-1)
        if lengths.dtype.kind not in "iu":
            raise ElicitError(f"'lengths' must be integers, got {lengths.dtype}", path)
        if (lengths <= 0).any():
            i = int(np.flatnonzero(lengths <= 0)[0])
            raise ElicitError(f"episode {i} is empty (lengths[{i}] = {lengths[i]})", path)
        if int(lengths.sum()) != n:
            raise ElicitError(f"'lengths' sum to {int(lengths.sum())} but 'obs' has {n} rows", path)
        stops = np.cumsum(lengths)
        return [
            (int(b - a), int(b), i) for i, (a, b) in enumerate(zip(lengths, stops, strict=True))
        ]
    if "episode_ids" in arrays:
        ids = np.asarray(arrays["episode_ids"]).reshape(-1)
        if len(ids) != n:
            raise ElicitError(f"'episode_ids' has {len(ids)} rows but 'obs' has {n}", path)
        if n == 0:
            return []
        change = np.flatnonzero(ids[1:] != ids[:-1]) + 1
        starts = np.concatenate([[0], change])
        stops = np.concatenate([change, [n]])
        seen: set = set()
        for s in starts:
            if ids[s].item() in seen:
                raise ElicitError(
                    f"episode id {ids[s].item()} is not contiguous (resumes at row {s})", path
                )
            seen.add(ids[s].item())
        return [(int(s), int(e), ids[s].item()) for s, e in zip(starts, stops, strict=True)]
    raise ElicitError("needs 'lengths' or 'episode_ids' to mark episode boundaries", path)


def _per_episode(
    arrays: dict[str, np.ndarray], key: str, bounds: list[tuple[int, int, Any]], n: int, path: Path
) -> list[Any] | None:
    if key not in arrays:
        return None
    v = np.asarray(arrays[key]).reshape(-1)
    if len(v) == len(bounds):
        return v.tolist()
    if len(v) == n:
        out = []
        for s, e, src in bounds:
            if len(set(v[s:e].tolist())) > 1:
                raise ElicitError(f"'{key}' changes within episode {src}", path)
            out.append(v[s].item())
        return out
    raise ElicitError(f"'{key}' has {len(v)} entries: expected {len(bounds)} or {n}", path)


def import_npz(
    path: str | Path,
    *,
    operator: str = "unknown",
    task: str | None = None,
    action_bounds: tuple[float, float] = (-1.0, 1.0),
    finite: bool = True,
) -> Demos:
    """Read a ``.npz`` of demonstrations (see the module docstring for its keys); with
    ``finite=False`` non-finite values are left for the caller to skip."""
    path = Path(path)
    arrays = load_arrays(path)
    if "obs" not in arrays:
        raise ElicitError(f"has no 'obs' array (keys: {', '.join(sorted(arrays))})", path)
    act_key = "act" if "act" in arrays else "action" if "action" in arrays else None
    if act_key is None:
        raise ElicitError(
            f"has no 'act' or 'action' array (keys: {', '.join(sorted(arrays))})", path
        )
    obs, act = np.asarray(arrays["obs"]), np.asarray(arrays[act_key])
    if obs.ndim != 2 or act.ndim != 2:
        raise ElicitError(f"'obs' and '{act_key}' must be 2-D, got {obs.shape}, {act.shape}", path)
    n = len(obs)
    if len(act) != n:
        raise ElicitError(f"'obs' has {n} rows but '{act_key}' has {len(act)}", path)
    if n == 0:
        raise ElicitError("holds no steps", path)
    bounds = _boundaries(arrays, n, path)
    ops = _per_episode(arrays, "operators", bounds, n, path) or [operator] * len(bounds)
    success = _per_episode(arrays, "success", bounds, n, path)
    rewards = arrays.get("rewards")
    if rewards is not None and len(rewards.reshape(-1)) != n:
        raise ElicitError(f"'rewards' has {rewards.size} entries but 'obs' has {n} rows", path)
    names = _per_episode(arrays, "source_episode", bounds, n, path) or [b[2] for b in bounds]
    episodes = []
    for (s, e, _), src in zip(bounds, names, strict=True):
        ep = {"obs": obs[s:e], "action": act[s:e], SOURCE_EPISODE: np.full(e - s, str(src), object)}
        if rewards is not None:
            ep["reward"] = rewards.reshape(-1)[s:e]
        episodes.append(ep)
    demos = from_episodes(
        episodes,
        operators=[str(o) for o in ops],
        successes=None if success is None else [bool(x) for x in success],
        task=task or "unknown",
        obs_fields=fields_from_sizes([("obs", obs.shape[1])]),
        action_low=float(action_bounds[0]),
        action_high=float(action_bounds[1]),
        provenance=make_provenance(
            path,
            "npz",
            action_key=act_key,
            boundaries="lengths" if "lengths" in arrays else "episode_ids",
            success_from="'success' array" if success is not None else "assumed (no 'success')",
        ),
    )
    return validate(demos, str(path), bounds=None, finite=finite)


def export_npz(demos: Demos, out: str | Path, header: dict[str, Any] | None = None) -> None:
    """Write ``demos`` to ``out`` as a ``.npz`` (atomically) that :func:`import_npz` reads back.

    Args:
      demos: the demonstrations (their episodes, in row order).
      out: destination path.
      header: an artifact header to embed as JSON text under ``elicit_jax_header``.
    """
    bounds = demos.episode_bounds()
    starts = [s for _, s, _ in bounds]
    source = demos.extra.get(SOURCE_EPISODE)
    arrays = {
        "obs": demos.obs.astype(np.float32),
        "act": demos.action.astype(np.float32),
        "lengths": np.array([e - s for _, s, e in bounds], np.int64),
        "episode_ids": demos.episode.astype(np.int64),
        "operators": demos.operator[starts].astype(str),
        "rewards": demos.reward.astype(np.float32),
        "success": demos.success[starts].astype(bool),
        "source_episode": (
            np.asarray(source)[starts].astype(str)
            if source is not None
            else np.array([str(e) for e, _, _ in bounds])
        ),
    }
    if header is not None:
        arrays["elicit_jax_header"] = np.array(dumps(header))
    with atomic_path(out) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)
