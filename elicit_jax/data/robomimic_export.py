"""Hand demonstrations to robomimic: a filter key in (a copy of) the source file, or a new file.

* :func:`add_mask` lists chosen demos under ``mask/<key>`` — in a copy of the source file, or
  in the file itself (``in_place``; everything else in it is hashed before and after and must
  be unchanged). robomimic then trains on them with ``train.hdf5_filter_key``.
* :func:`write_fresh` writes any demonstrations as a new robomimic 0.3 file:
  ``data/demo_i/{obs/<field>, next_obs/<field>, actions, rewards, dones}`` with
  ``num_samples``, ``data.attrs['env_args']`` and ``total``, one mask per operator (named
  after it) and ``train``/``valid`` masks. What robomimic has no place for is said in the
  returned notes (and stored with the file's provenance), never dropped silently.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import stat
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import atomic_path, dumps
from elicit_jax.data.demos import Demos, episode_digest
from elicit_jax.data.hdf5_write import edit_copy, hdf5_reason, write_new_hdf5
from elicit_jax.data.robomimic import demo_names, open_hdf5, read_demo
from elicit_jax.errors import ElicitError

SPLIT_MASKS = ("train", "valid")
PRE_FILTER_STEP = "pre_filter_step"  # written by `elicit-jax filter --level pair`


def demo_order(name: str) -> int:
    """robomimic's order of demos: by the number in ``demo_N``."""
    return int(name[5:]) if name.startswith("demo_") and name[5:].isdigit() else -1


def read_demo_digests(
    path: str | Path, names: Sequence[str], obs_keys: Sequence[str]
) -> dict[str, tuple[int, str]]:
    """``name -> (steps, content hash)`` of the named demos, as an import would see them."""
    out = {}
    with open_hdf5(path) as f:
        present = set(demo_names(f, path))
        for name in names:
            if name not in present:
                raise ElicitError(f"has no demo '{name}'", path)
            ep, _ = read_demo(f, path, name, obs_keys)
            out[name] = (
                len(ep["action"]),
                episode_digest(ep["obs"], ep["action"], ep.get("reward")),
            )
    return out


def content_digest(
    path: str | Path, skip: str, progress: Callable[[int], None] | None = None
) -> str:
    """Hash of every object in an HDF5 file — names, attributes, dtypes, shapes and data —
    except the dataset ``skip`` (and the existence of its parent group)."""
    h = hashlib.sha256()
    parent = skip.rsplit("/", 1)[0] if "/" in skip else ""

    def attrs(obj: Any) -> None:
        for k in sorted(obj.attrs.keys()):
            h.update(k.encode())
            h.update(repr(np.asarray(obj.attrs[k]).tolist()).encode())

    def visit(name: str, obj: Any) -> None:
        if name == skip or (name == parent and not len(obj.attrs)):
            return
        h.update(name.encode())
        attrs(obj)
        if hasattr(obj, "dtype"):
            h.update(f"{obj.dtype.str}{obj.shape}".encode())
            if obj.shape and obj.size:
                step = max(1, (64 << 20) // max(1, obj.dtype.itemsize * obj.size // obj.shape[0]))
                for i in range(0, obj.shape[0], step):
                    block = np.ascontiguousarray(obj[i : i + step])
                    h.update(
                        repr(block.tolist()).encode() if block.dtype == object else block.tobytes()
                    )
                    if progress is not None:
                        progress(block.nbytes)
            elif obj.shape == ():
                h.update(np.asarray(obj[()]).tobytes())

    with open_hdf5(path) as f:
        attrs(f)
        f.visititems(visit)
    return h.hexdigest()


def mask_dataset(
    mask_key: str, names: Sequence[str], header: dict[str, Any] | None
) -> dict[str, tuple[np.ndarray, dict[str, str]]]:
    """The ``mask/<mask_key>`` dataset to write: HDF5 path -> (names, attributes)."""
    attrs = {} if header is None else {"elicit_jax": dumps(header)}
    return {f"mask/{mask_key}": (np.array(names, dtype="S"), attrs)}


def _read_back(path: Path, mask_key: str, names: Sequence[str]) -> None:
    """Error unless the file at ``path`` opens and lists exactly ``names`` in the mask."""
    try:
        with open_hdf5(path) as f:
            listed = [x.decode() for x in f["mask"][mask_key][:]]
    except (ElicitError, OSError, KeyError, RuntimeError, ValueError) as e:
        raise ElicitError(f"the written copy does not read back ({hdf5_reason(e)})") from e
    if listed != list(names):
        raise ElicitError(f"the written copy's mask/{mask_key} does not read back as written")


def add_mask(
    source: str | Path,
    out: str | Path | None,
    mask_key: str,
    demos: Sequence[str],
    *,
    overwrite: bool = False,
    header: dict[str, Any] | None = None,
    progress: Callable[[int], None] | None = None,
) -> list[str]:
    """Add ``mask/<mask_key>`` listing ``demos`` to a copy of ``source`` (or to ``source``).

    Either way the mask is written into a copy (:func:`elicit_jax.data.hdf5_write.edit_copy`)
    that is flushed to disk and read back before it is renamed into place, so a full disk,
    a file-size limit or a kill leaves ``source`` as it was.

    Args:
      source: the robomimic file.
      out: the copy to write (atomically); ``None`` replaces ``source`` itself with its
        masked copy (same path, same permissions; a symlink's target is the file replaced)
        after checking that nothing but the new mask differs (a full read of both files).
      mask_key: the new filter key.
      demos: demo names, e.g. ``["demo_0", "demo_12"]``.
      overwrite: replace an existing ``mask/<mask_key>``.
      header: elicit-jax artifact header, stored as JSON in the mask's ``elicit_jax``
        attribute (robomimic ignores it).
      progress: called with the number of bytes hashed, for a progress bar (in place only).

    Returns:
      The demo names written, in robomimic's numeric order.

    Raises:
      ElicitError: a bad key or demo, or the write failed; in place, the message says the
        source file was not changed.
    """
    source = Path(source)
    if not mask_key or "/" in mask_key:
        raise ElicitError(f"invalid mask key {mask_key!r}")
    if out is not None and Path(out).resolve() == source.resolve():
        raise ElicitError("output must differ from the source file (or pass --in-place)", out)
    chosen = sorted(set(demos), key=demo_order)
    if not chosen:
        raise ElicitError("no demonstrations selected: refusing to write an empty mask")
    with open_hdf5(source) as f:
        present = set(demo_names(f, source))
        missing = [n for n in chosen if n not in present]
        if missing:
            raise ElicitError(f"has no demo '{missing[0]}' to put in mask/{mask_key}", source)
        if "mask" in f and mask_key in f["mask"] and not overwrite:
            raise ElicitError(
                f"already has mask/{mask_key}; pick another --mask-key or pass --overwrite",
                source,
            )
    edit = mask_dataset(mask_key, chosen, header)
    needs = sum(len(n) + 1 for n in chosen) + (len(dumps(header)) if header else 0)
    if out is not None:
        with atomic_path(out) as tmp:
            try:
                edit_copy(source, tmp, edit, needs)
                _read_back(tmp, mask_key, chosen)
            except ElicitError as e:
                text = f"cannot write the masked copy ({e}); nothing written"
                raise ElicitError(text, out) from e
        return chosen
    _replace_with_masked_copy(source, mask_key, chosen, edit, needs, progress)
    return chosen


def _replace_with_masked_copy(
    source: Path,
    mask_key: str,
    chosen: list[str],
    edit: dict[str, tuple[np.ndarray, dict[str, str]]],
    needs: int,
    progress: Callable[[int], None] | None,
) -> None:
    """``--in-place``: write the mask into a copy beside ``source``, check the copy (nothing
    but the mask differs, the mask reads back, ``source`` did not change meanwhile), then
    rename it over ``source``; on any failure ``source`` is left exactly as it was."""
    target = source.resolve()
    if not os.access(target, os.W_OK):
        raise ElicitError("is read-only; the source file was not changed", source)
    skip = f"mask/{mask_key}"
    was = target.stat()
    try:
        before = content_digest(target, skip, progress)
        with atomic_path(target) as tmp:
            edit_copy(target, tmp, edit, needs)
            if content_digest(tmp, skip, progress) != before:
                raise ElicitError(f"content other than mask/{mask_key} changed in the copy")
            _read_back(tmp, mask_key, chosen)
            now = target.stat()
            if (now.st_ino, now.st_size, now.st_mtime_ns) != (
                was.st_ino,
                was.st_size,
                was.st_mtime_ns,
            ):
                raise ElicitError("another program changed the file while the mask was added")
            os.chmod(tmp, stat.S_IMODE(was.st_mode))
            if (was.st_uid, was.st_gid) != (os.geteuid(), os.getegid()):
                with contextlib.suppress(OSError):
                    os.chown(tmp, was.st_uid, was.st_gid)
    except ElicitError as e:
        why = str(e).removeprefix(f"{e.path}: ") if e.path else str(e)
        raise ElicitError(
            f"cannot add mask/{mask_key} in place ({why}); the source file was not changed",
            source,
        ) from e


def _obs_layout(demos: Demos) -> list[tuple[str, int, int]]:
    """``(key, start, stop)`` per robomimic obs key: the demos' fields if they tile obs."""
    fields = sorted(demos.obs_fields, key=lambda f: f.start)
    stops = [0] + [f.stop for f in fields]
    if (
        fields
        and all(f.start == s for f, s in zip(fields, stops, strict=False))
        and (stops[-1] == demos.obs_dim)
    ):
        for f in fields:
            if not f.name or "/" in f.name:
                raise ElicitError(f"obs field {f.name!r} cannot name a robomimic obs key")
        return [(f.name, f.start, f.stop) for f in fields]
    return [("obs", 0, demos.obs_dim)]


def _masks(
    names: list[str], operators: list[str], valid_fraction: float, seed: int
) -> dict[str, list[str]]:
    masks: dict[str, list[str]] = {}
    for name, op in zip(names, operators, strict=True):
        if op in SPLIT_MASKS or not op or "/" in op:
            raise ElicitError(
                f"operator name {op!r} cannot be a robomimic mask key (it clashes with the "
                f"{'/'.join(SPLIT_MASKS)} split or is not a valid name)"
            )
        masks.setdefault(op, []).append(name)
    n_valid = max(1, int(valid_fraction * len(names))) if valid_fraction > 0 else 0
    if len(names) >= 2 and n_valid:
        valid = set(np.random.default_rng(seed).permutation(len(names))[:n_valid].tolist())
        masks["train"] = [n for i, n in enumerate(names) if i not in valid]
        masks["valid"] = [n for i, n in enumerate(names) if i in valid]
    return masks


def _extras(
    demos: Demos, bounds: list[tuple[int, int, int]]
) -> tuple[dict[str, Any], dict[str, str]]:
    """Extra columns split into per-demo attributes (constant in every episode) and per-step
    datasets; returns ``(kinds, where)`` with where each one goes."""
    kinds: dict[str, Any] = {}
    where = {}
    for k, v in sorted(demos.extra.items()):
        v = np.asarray(v)
        const = all((v[s:e] == v[s]).all() for _, s, e in bounds)
        kinds[k] = "attr" if const and v.ndim == 1 else "dataset"
        where[k] = "attribute of each demo" if kinds[k] == "attr" else "data/demo_i/extras/" + k
    return kinds, where


def write_fresh(
    demos: Demos,
    out: str | Path,
    *,
    env_args: dict[str, Any] | None = None,
    valid_fraction: float = 0.1,
    seed: int = 0,
    header: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Write ``demos`` as a new robomimic file, one demo per episode in row order.

    Args:
      demos: the demonstrations.
      out: the ``.hdf5`` to write (atomically).
      env_args: robomimic environment metadata to store (e.g. the source file's); default
        ``{"env_name": demos.task, "type": 2, "env_kwargs": {}}``, which robomimic can
        read but not instantiate (said in the notes).
      valid_fraction: share of demos in ``mask/valid`` (at least one when > 0 and there
        are two demos or more); the rest are in ``mask/train``. Seeded by ``seed``.
      header: provenance, stored as JSON in ``data.attrs['elicit_jax']``.

    Returns:
      ``demos`` (names), ``obs_keys``, ``masks`` (key -> count) and ``notes`` (what robomimic
      has no place for, and where it went).
    """
    bounds = demos.episode_bounds()
    names = [f"demo_{i}" for i in range(len(bounds))]
    layout = _obs_layout(demos)
    masks = _masks(names, [str(demos.operator[s]) for _, s, _ in bounds], valid_fraction, seed)
    kinds, where = _extras(demos, bounds)
    notes = _fresh_notes(demos, bounds, layout, env_args, where)
    env = env_args or {"env_name": demos.task, "type": 2, "env_kwargs": {}}

    def build(f: Any) -> None:
        data = f.create_group("data")
        data.attrs["env_args"] = json.dumps(env)
        data.attrs["total"] = demos.n_steps
        if header is not None:
            data.attrs["elicit_jax"] = dumps({**header, "notes": notes})
        for name, (e, s, t) in zip(names, bounds, strict=True):
            g = data.create_group(name)
            obs = demos.obs[s:t]
            g.create_dataset("actions", data=demos.action[s:t])
            g.create_dataset("rewards", data=demos.reward[s:t])
            dones = np.zeros(t - s, np.int64)
            dones[-1] = 1
            g.create_dataset("dones", data=dones)
            for key, a, b in layout:
                g.create_dataset(f"obs/{key}", data=obs[:, a:b])
                g.create_dataset(
                    f"next_obs/{key}", data=np.concatenate([obs[1:, a:b], obs[-1:, a:b]])
                )
            g.attrs["num_samples"] = t - s
            g.attrs["episode"] = e
            g.attrs["operator"] = str(demos.operator[s])
            g.attrs["success"] = bool(demos.success[s])
            for k, kind in kinds.items():
                v = np.asarray(demos.extra[k][s:t])
                if kind == "attr":
                    g.attrs[k] = str(v[0]) if v.dtype == object else v[0]
                else:
                    g.create_dataset(f"extras/{k}", data=v.astype("S") if v.dtype == object else v)
        for key, listed in masks.items():
            f.create_dataset(f"mask/{key}", data=np.array(listed, dtype="S"))

    write_new_hdf5(out, build)
    return {
        "demos": names,
        "obs_keys": [k for k, _, _ in layout],
        "masks": {k: len(v) for k, v in masks.items()},
        "notes": notes,
    }


def _fresh_notes(
    demos: Demos,
    bounds: list[tuple[int, int, int]],
    layout: list[tuple[str, int, int]],
    env_args: dict[str, Any] | None,
    extras: dict[str, str],
) -> list[str]:
    """What a robomimic file of these demos cannot hold as they are, said plainly."""
    notes = [
        "no simulator states (data/demo_i/states) or model_file: the demos hold none, so "
        "robomimic's playback and observation-extraction scripts cannot replay them",
        "next_obs is obs one step later; each demo's last next_obs repeats its last obs "
        "(the demos record no observation after the final action)",
    ]
    if layout == [("obs", 0, demos.obs_dim)] and demos.obs_fields:
        notes.append("obs fields do not tile the observation: written whole as obs/obs")
    if env_args is None:
        notes.append(
            f"env_args names task '{demos.task}', which robomimic cannot instantiate: train "
            "with config.experiment.rollout.enabled=False"
        )
    rewarded = [bool(demos.reward[s:e].max() >= 1.0) for _, s, e in bounds]
    differ = sum(r != bool(demos.success[s]) for r, (_, s, _) in zip(rewarded, bounds, strict=True))
    if differ:
        notes.append(
            f"{differ} demos' success differs from max(rewards) >= 1, which is how robomimic "
            "datasets (and elicit-jax's import) tell success; kept in each demo's 'success' "
            "attribute"
        )
    lo, hi = np.min(demos.action_low), np.max(demos.action_high)
    if lo < -1.0 or hi > 1.0:
        notes.append(
            f"actions span [{lo:g}, {hi:g}], beyond robomimic's usual [-1, 1]; re-import with "
            "--action-bounds data"
        )
    if PRE_FILTER_STEP in demos.extra:
        pre = np.asarray(demos.extra[PRE_FILTER_STEP])
        gaps = sum(bool((np.diff(pre[s:e]) != 1).any()) for _, s, e in bounds)
        if gaps:
            notes.append(
                f"{gaps} demos join steps across dropped pairs (filter --pair-mode renumber): "
                "sequence models (BC-RNN, frame stacking) see jumps there; filter with "
                "--pair-mode split to write contiguous pieces"
            )
    if extras:
        notes.append("extra columns kept: " + "; ".join(f"{k} as {w}" for k, w in extras.items()))
    return notes
