"""robomimic HDF5 datasets: read them into :class:`Demos` (writing: :mod:`robomimic_export`).

Layout (robomimic v0.x): ``data/demo_N/{actions (T, A), rewards (T,), dones (T,),
obs/<key> (T, ...)}`` with ``data/demo_N.attrs['num_samples']``; ``data.attrs['env_args']``
is a JSON string whose ``env_name`` names the task; ``mask/<filter_key>`` holds byte strings
of demo names. robomimic orders demos by their number, so do we.
"""

from __future__ import annotations

import contextlib
import fnmatch
import json
import re
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.data.demos import (
    SOURCE_EPISODE,
    Demos,
    DemosWarning,
    episode_digest,
    fields_from_sizes,
    from_episodes,
    make_provenance,
    validate,
)
from elicit_jax.errors import ElicitError

DEFAULT_OBS_KEYS = ("robot0_eef_pos", "robot0_eef_quat", "robot0_gripper_qpos", "object")
_DEMO_RE = re.compile(r"demo_(\d+)\Z")

#: ``progress(items, description)`` -> the same items, iterated while showing progress.
Progress = Callable[[Sequence[str], str], Iterable[str]]


@contextlib.contextmanager
def open_hdf5(path: str | Path, mode: str = "r") -> Iterator[Any]:
    """Open an HDF5 file, turning a missing or unreadable file into an :class:`ElicitError`."""
    import h5py

    path = Path(path)
    if path.is_dir():
        raise ElicitError("is a folder, not an HDF5 file", path)
    if not path.is_file():
        raise ElicitError("file not found", path)
    try:
        f = h5py.File(path, mode)
    except OSError as e:
        raise ElicitError(f"not a readable HDF5 file ({e})", path) from e
    with f:
        yield f


def demo_names(f: Any, path: str | Path) -> list[str]:
    """Names of the demos under ``data``, sorted by number as robomimic does."""
    if "data" not in f:
        raise ElicitError("no 'data' group (not a robomimic dataset?)", path)
    names = list(f["data"].keys())
    bad = [n for n in names if not _DEMO_RE.match(n)]
    if bad:
        raise ElicitError(f"unexpected entry data/{bad[0]} (robomimic expects demo_N)", path)
    if not names:
        raise ElicitError("no demonstrations under 'data'", path)
    return sorted(names, key=lambda n: int(n[5:]))


def read_mask(f: Any, key: str, path: str | Path) -> list[str]:
    """Demo names listed by ``mask/<key>`` (stored as byte strings)."""
    if "mask" not in f or key not in f["mask"]:
        have = sorted(f["mask"].keys()) if "mask" in f else []
        raise ElicitError(
            f"no mask/{key} (available filter keys: {', '.join(have) or 'none'})", path
        )
    return [x.decode() if isinstance(x, bytes) else str(x) for x in np.asarray(f["mask"][key][:])]


def env_args(f: Any, path: str | Path) -> dict[str, Any] | None:
    """``data.attrs['env_args']`` parsed (robomimic's environment metadata), or ``None``."""
    raw = f["data"].attrs.get("env_args")
    if raw is None:
        return None
    try:
        args = json.loads(raw.decode() if isinstance(raw, bytes) else str(raw))
    except json.JSONDecodeError as e:
        raise ElicitError(f"data.attrs['env_args'] is not valid JSON ({e.msg})", path) from e
    return args if isinstance(args, dict) else None


def task_name(f: Any, path: str | Path) -> str:
    """The task (``env_name`` of ``data.attrs['env_args']``), or ``unknown``."""
    args = env_args(f, path)
    return str(args.get("env_name", "unknown")) if args else "unknown"


def _operator_labels(
    f: Any, path: str | Path, names: Sequence[str], pattern: str, default: str
) -> list[str]:
    patterns = [p.strip() for p in pattern.split(",") if p.strip()]
    keys = sorted(
        k
        for k in (f["mask"].keys() if "mask" in f else [])
        if any(fnmatch.fnmatch(k, p) for p in patterns)
    )
    if not keys:
        raise ElicitError(f"no mask key matches '{pattern}'", path)
    label: dict[str, str] = {}
    present = set(demo_names(f, path))
    for key in keys:
        for demo in read_mask(f, key, path):
            if demo not in present:
                raise ElicitError(
                    f"mask/{key} lists {demo}, which is not in the file (no data/{demo}): "
                    "a stale mask would label the wrong demos; fix or delete the mask",
                    path,
                )
            if demo in label:
                raise ElicitError(
                    f"{demo} is listed by both mask/{label[demo]} and mask/{key}", path
                )
            label[demo] = key
    unlisted = [n for n in names if n not in label]
    if unlisted:
        warnings.warn(
            f"{path}: {len(unlisted)} demos (e.g. {unlisted[0]}) are listed by no mask matching "
            f"'{pattern}'; labelled '{default}'",
            DemosWarning,
            stacklevel=3,
        )
    return [label.get(n, default) for n in names]


def numeric_dataset(f: Any, key: str, path: str | Path) -> np.ndarray:
    """``f[key]`` as float32; a dataset of bytes, strings or other non-numbers is an error
    naming the file and the dataset (not numpy's "could not convert string to float")."""
    data = f[key]
    kind = getattr(data.dtype, "kind", "O")
    if kind not in "biuf":
        raise ElicitError(
            f"{key} holds {data.dtype} values, not numbers (bytes or text where a robomimic "
            "file has floats)",
            path,
        )
    return np.asarray(data[:], np.float32)


def read_demo(
    f: Any, path: str | Path, name: str, obs_keys: Sequence[str]
) -> tuple[dict[str, np.ndarray], tuple[int, ...]]:
    """One demo as ``{"obs" (T, O) float32, "action" (T, A), "reward" (T,) if any}`` and the
    width of each obs key."""
    g = f["data"][name]
    if "actions" not in g:
        raise ElicitError(f"data/{name} has no 'actions'", path)
    action = numeric_dataset(f, f"data/{name}/actions", path)
    t = len(action)
    if t == 0:
        raise ElicitError(f"data/{name} is empty (0 steps)", path)
    if action.ndim != 2:
        raise ElicitError(f"data/{name}/actions must be (T, A), got {action.shape}", path)
    n_samples = g.attrs.get("num_samples")
    if n_samples is not None and int(n_samples) != t:
        raise ElicitError(f"data/{name}: num_samples={int(n_samples)} but actions has {t}", path)
    parts = []
    for key in obs_keys:
        if "obs" not in g or key not in g["obs"]:
            have = sorted(g["obs"].keys()) if "obs" in g else []
            raise ElicitError(
                f"data/{name}/obs has no '{key}' (available: {', '.join(have) or 'none'}); "
                "choose keys with --obs-keys",
                path,
            )
        shape = g["obs"][key].shape
        if len(shape) > 2:
            raise ElicitError(
                f"data/{name}/obs/{key} has shape {shape}: image keys are not supported", path
            )
        arr = numeric_dataset(f, f"data/{name}/obs/{key}", path)
        if len(arr) != t:
            raise ElicitError(f"data/{name}/obs/{key} has {len(arr)} steps, actions {t}", path)
        parts.append(arr.reshape(t, -1).astype(np.float32))
    ep = {"obs": np.concatenate(parts, axis=1), "action": action}
    if "rewards" in g:
        ep["reward"] = numeric_dataset(f, f"data/{name}/rewards", path).reshape(-1)
        if len(ep["reward"]) != t:
            raise ElicitError(f"data/{name}/rewards has {len(ep['reward'])} steps, not {t}", path)
    ep[SOURCE_EPISODE] = np.full(t, name, dtype=object)
    return ep, tuple(p.shape[1] for p in parts)


def _selected_names(f: Any, path: str | Path, filter_key: str | None) -> list[str]:
    """The demos to import, in demo_N order: all, or those ``mask/<filter_key>`` lists."""
    names = demo_names(f, path)
    if filter_key is None:
        return names
    wanted = set(read_mask(f, filter_key, path))
    unknown = sorted(wanted - set(names))
    if unknown:
        raise ElicitError(f"mask/{filter_key} lists missing demo {unknown[0]}", path)
    names = [n for n in names if n in wanted]
    if not names:
        raise ElicitError(f"mask/{filter_key} lists no demos", path)
    return names


def _read_demos(
    f: Any,
    path: str | Path,
    names: list[str],
    obs_keys: tuple[str, ...],
    progress: Progress | None,
) -> tuple[list[dict[str, Any]], tuple[int, ...] | None, dict[str, str]]:
    """Each demo's episode columns, the obs keys' sizes (the same in every demo) and each
    demo's content digest."""
    iterator: Iterable[str] = names
    if progress is not None:
        iterator = progress(names, f"reading {Path(path).name}")
    episodes, sizes, digests = [], None, {}
    for name in iterator:
        ep, widths = read_demo(f, path, name, obs_keys)
        digests[name] = episode_digest(ep["obs"], ep["action"], ep.get("reward"))
        if sizes is not None and widths != sizes:
            raise ElicitError(
                f"data/{name}: obs key sizes {widths} differ from {names[0]}'s {sizes}", path
            )
        episodes.append(ep)
        sizes = widths
    return episodes, sizes, digests


def import_robomimic(
    path: str | Path,
    *,
    obs_keys: Sequence[str] | None = None,
    operator: str = "unknown",
    operators_from_masks: str | None = None,
    filter_key: str | None = None,
    task: str | None = None,
    action_bounds: tuple[float, float] = (-1.0, 1.0),
    progress: Progress | None = None,
    finite: bool = True,
) -> Demos:
    """Read a robomimic HDF5 file into :class:`Demos` (episodes 0..E-1 in demo_N order).

    Args:
      path: the ``.hdf5`` file.
      obs_keys: observation keys concatenated in this order; default the standard low-dim
        set :data:`DEFAULT_OBS_KEYS`.
      operator: operator label of every demo (or of demos no matching mask lists).
      operators_from_masks: glob over mask keys, e.g. ``*_operator_*``, or several
        comma-separated (``base,conflict``); each demo is labelled by the (single) matching
        mask that lists it.
      filter_key: import only the demos listed by ``mask/<filter_key>``.
      task: task name; default the ``env_name`` in ``data.attrs['env_args']``.
      action_bounds: declared action bounds (robomimic actions lie in [-1, 1]).
      progress: wraps the demo names to show progress (``progress(names, description)``
        returns an iterable over them; the CLI passes a progress bar).
      finite: reject non-finite values here (False: the caller skips such episodes).

    The episode outcome is ``max(rewards) >= 1`` (robosuite's sparse success reward), or
    assumed successful when the file has no rewards; ``provenance['success_from']`` says which.
    """
    obs_keys = tuple(obs_keys or DEFAULT_OBS_KEYS)
    with open_hdf5(path) as f:
        names = _selected_names(f, path, filter_key)
        labels = (
            _operator_labels(f, path, names, operators_from_masks, operator)
            if operators_from_masks
            else [operator] * len(names)
        )
        episodes, sizes, digests = _read_demos(f, path, names, obs_keys, progress)
        env_task = task_name(f, path)
        env = env_args(f, path)
    has_rewards = all("reward" in ep for ep in episodes)
    if not has_rewards:
        for ep in episodes:
            ep.pop("reward", None)
    successes = [bool(ep["reward"].max() >= 1.0) if has_rewards else True for ep in episodes]
    demos = from_episodes(
        episodes,
        operators=labels,
        successes=successes,
        task=task or env_task,
        obs_fields=fields_from_sizes(list(zip(obs_keys, sizes, strict=True))),
        action_low=float(action_bounds[0]),
        action_high=float(action_bounds[1]),
        provenance=make_provenance(
            path,
            "robomimic",
            obs_keys=list(obs_keys),
            filter_key=filter_key,
            operators_from_masks=operators_from_masks,
            success_from="max(rewards) >= 1" if has_rewards else "assumed (no rewards)",
            env_args=env,
            episode_sha256=digests,
        ),
    )
    return validate(demos, str(path), bounds=None, finite=finite)
