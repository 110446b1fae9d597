"""Invariants of a demonstration set, checked on every write and read.

Each failure is one :class:`~elicit_jax.errors.ElicitError` line naming the file and, where
it applies, the episode (with its name in the source dataset) and step.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Literal

import numpy as np

from elicit_jax.data.demo_set import ARRAY_FIELDS, SOURCE_EPISODE, Demos, ObsField
from elicit_jax.errors import ElicitError

BoundsPolicy = Literal["error", "warn", "clip"]
MAX_MAGNITUDE = 1e6
"""Largest ``|value|`` accepted in obs and action: beyond it a value is a unit or sensor
error (one value of 1e30 makes its column's std about 2e28, which erases the feature after
normalisation, and float32 squares of it overflow); such data is refused, not trained on."""


class DemosWarning(UserWarning):
    """Accepted but suspicious data (e.g. out-of-bounds actions under ``bounds='warn'``)."""


def _first_bad_row(bad: np.ndarray) -> int:
    return int(np.flatnonzero(bad)[0])


def _where(demos: Demos, row: int) -> str:
    """``episode E (source name), step S`` of a row."""
    names = demos.extra.get(SOURCE_EPISODE)
    src = f" ({names[row]})" if names is not None and len(names) == demos.n_steps else ""
    return f"episode {demos.episode[row]}{src}, step {demos.step[row]}"


def validate(
    demos: Demos,
    source: str = "<demos>",
    bounds: BoundsPolicy | None = "error",
    finite: bool = True,
) -> Demos:
    """Check a :class:`Demos` for consistency; returns it (clipped if ``bounds='clip'``).

    Checks: matching row counts, 2-D obs/action, finite values, at least one episode,
    contiguous episodes, steps 0..T-1 in order, one operator and one outcome per episode,
    obs fields within obs_dim, actions within their declared bounds. Importers skip the
    bounds (``bounds=None``: the user's bounds policy applies afterwards) and, when asked to
    skip bad episodes, the finiteness check (``finite=False``); every write checks all.
    """
    n = demos.obs.shape[0] if demos.obs.ndim else 0
    if demos.obs.ndim != 2 or demos.action.ndim != 2:
        raise ElicitError(
            f"obs and action must be 2-D, got {demos.obs.shape} and {demos.action.shape}", source
        )
    for k in ARRAY_FIELDS:
        if len(getattr(demos, k)) != n:
            raise ElicitError(
                f"column '{k}' has {len(getattr(demos, k))} rows, expected {n}", source
            )
    for k, v in demos.extra.items():
        if len(v) != n:
            raise ElicitError(f"extra column '{k}' has {len(v)} rows, expected {n}", source)
    if n == 0:
        raise ElicitError("holds no steps (empty demonstration set)", source)
    for name in ("obs", "action", "reward") if finite else ():
        bad = ~np.isfinite(getattr(demos, name))
        if bad.any():
            row, *col = (int(x) for x in np.argwhere(bad)[0])
            where = f"[{col[0]}]" if col else ""
            raise ElicitError(f"non-finite {name}{where} value at {_where(demos, row)}", source)
    if finite:
        check_magnitudes(
            {"obs": demos.obs, "action": demos.action},
            lambda row: _where(demos, row),
            source,
            demos.obs_fields,
        )
    for name in set(demos.operator.tolist()):
        check_operator_name(name, source)
    check_episode_layout(
        demos.episode,
        demos.step,
        {"operator": demos.operator, "success": demos.success},
        source,
    )
    names = [f.name for f in demos.obs_fields]
    if len(names) != len(set(names)):
        raise ElicitError(f"duplicate obs field names in {names}", source)
    for f in demos.obs_fields:
        if not 0 <= f.start < f.stop <= demos.obs_dim:
            raise ElicitError(
                f"obs field '{f.name}' {f.start}:{f.stop} lies outside obs_dim {demos.obs_dim}",
                source,
            )
    return demos if bounds is None else _check_bounds(demos, source, bounds)


def check_operator_name(name: str, source: str) -> None:
    """An operator label is printable text on one line (it names files, pages and table rows).

    Raises:
      ElicitError: a newline, tab or other control character in ``name``, naming ``source``
        (the file, or the flag it came from).
    """
    if not str(name).isprintable():
        raise ElicitError(
            f"operator name {str(name)!r} holds a newline or another non-printable "
            "character; operator names are printable text on one line",
            source,
        )


def check_episode_layout(
    episode: np.ndarray,
    step: np.ndarray,
    constant: Mapping[str, np.ndarray],
    source: str,
) -> None:
    """Check that episodes are contiguous, their steps run 0..T-1 in order and each column of
    ``constant`` (operator, success) holds one value per episode.

    Every reader of a demos artifact checks this: :func:`validate` on whole sets, and the
    scorer, which streams obs and actions, on these columns alone.

    Raises:
      ElicitError: one line naming ``source`` and the first episode that breaks a rule.
    """
    episode = np.asarray(episode)
    if not len(episode):
        return
    starts = np.flatnonzero(np.r_[True, episode[1:] != episode[:-1]])
    stops = np.r_[starts[1:], len(episode)]
    seen: dict[int, int] = {}
    for s in starts:
        e = int(episode[s])
        if e in seen:
            raise ElicitError(
                f"episode {e} is not contiguous: its rows resume at row {s} (step "
                f"{step[s]}) after other episodes",
                source,
            )
        seen[e] = int(s)
    for s, stop in zip(starts, stops, strict=True):
        e = int(episode[s])
        steps = np.asarray(step[s:stop])
        expect = np.arange(stop - s)
        if not np.array_equal(steps, expect):
            i = _first_bad_row(steps != expect)
            raise ElicitError(
                f"episode {e}: steps must run 0..{stop - s - 1} in order, "
                f"found step {steps[i]} at position {i}",
                source,
            )
        for name, values in constant.items():
            col = np.asarray(values[s:stop])
            if len(set(col.tolist())) > 1:
                i = _first_bad_row(col != col[0])
                raise ElicitError(
                    f"episode {e}: {name} changes within the episode at step {i} "
                    f"({col[0]!r} -> {col[i]!r})",
                    source,
                )


def check_magnitudes(
    arrays: Mapping[str, np.ndarray],
    where: Callable[[int], str],
    source: str,
    obs_fields: Sequence[ObsField] = (),
) -> None:
    """Refuse finite values beyond :data:`MAX_MAGNITUDE` in 2-D ``arrays`` (obs, action).

    Args:
      arrays: column name -> (rows, width) values (already known to be finite).
      where: row -> ``episode E, step S`` for the message.
      source: the file named in the message.
      obs_fields: the obs field slices, to name the field an obs column belongs to.

    Raises:
      ElicitError: one line naming the file, episode, step and column of the first such value.
    """
    for name, values in arrays.items():
        if not values.size or -MAX_MAGNITUDE <= values.min() <= values.max() <= MAX_MAGNITUDE:
            continue  # (no |values| copy of a large array in the common case)
        big = np.abs(values) > MAX_MAGNITUDE
        row, col = (int(x) for x in np.argwhere(big.reshape(len(values), -1))[0])
        field = next((f for f in obs_fields if f.start <= col < f.stop), None)
        named = f" ('{field.name}'[{col - field.start}])" if name == "obs" and field else ""
        value = float(values.reshape(len(values), -1)[row, col])
        raise ElicitError(
            f"{name}[{col}]{named} = {value:.4g} at {where(row)}: beyond ±{MAX_MAGNITUDE:.0e}, "
            f"a unit or sensor error ({int(big.any(axis=-1).sum())} steps in all); it would "
            "erase the column after normalisation: fix or rescale the data",
            source,
        )


def bad_episodes(demos: Demos) -> dict[int, str]:
    """Episode id -> why it cannot be used (non-finite obs, action or reward, or obs/action
    beyond :data:`MAX_MAGNITUDE`), for importers asked to skip such episodes rather than
    fail."""
    out: dict[int, str] = {}
    for name in ("obs", "action", "reward"):
        values = getattr(demos, name).reshape(len(demos.step), -1)
        finite = np.isfinite(values)
        checks = [("non-finite", ~finite.all(axis=1))]
        if name != "reward":
            huge = (np.abs(np.where(finite, values, 0)) > MAX_MAGNITUDE).any(axis=1)
            checks.append((f"|value| > {MAX_MAGNITUDE:.0e} in", huge))
        for what, bad in checks:
            for row in np.flatnonzero(bad):
                e = int(demos.episode[row])
                out.setdefault(e, f"{what} {name} at step {int(demos.step[row])}")
    return out


def action_dim_warnings(action: np.ndarray, ratio: float = 5.0) -> list[str]:
    """Action dims that distort ℓ (a mean over dims of raw squared errors).

    Returns messages for dims that never change (they add nothing to ℓ but dilute its mean)
    and for one dim whose spread exceeds ``ratio`` times the median of the others' (e.g. a
    ±1 gripper among small deltas: it dominates ℓ).
    """
    action = np.asarray(action, np.float64)
    if action.ndim != 2 or not len(action):
        return []
    std = action.std(axis=0)
    out = []
    const = np.flatnonzero(std < 1e-6)
    if len(const):
        values = ", ".join(f"{int(d)}: {action[0, d]:.3g}" for d in const)
        out.append(
            f"action dims {const.tolist()} are constant ({values}): they add nothing to the "
            "likelihood error but dilute its mean over dims; `score --action-scale std` scores "
            "them in units of the other dims' median std"
        )
    varying = np.flatnonzero(std >= 1e-6)
    if len(varying) >= 2:
        top = int(varying[np.argmax(std[varying])])
        rest = float(np.median(std[varying[varying != top]]))
        if std[top] > ratio * rest:
            out.append(
                f"action dim {top} varies {std[top] / rest:.0f}x more than the others (std "
                f"{std[top]:.2g} vs a median {rest:.2g}; e.g. a ±1 gripper): it dominates the "
                "likelihood error; `score --action-scale std` weighs every dim by its spread"
            )
    return out


def _check_bounds(demos: Demos, source: str, bounds: BoundsPolicy) -> Demos:
    try:
        lo = np.broadcast_to(np.asarray(demos.action_low, np.float32), (demos.action_dim,))
        hi = np.broadcast_to(np.asarray(demos.action_high, np.float32), (demos.action_dim,))
    except ValueError as e:
        raise ElicitError(
            f"action bounds {demos.action_low}..{demos.action_high} do not match "
            f"action_dim {demos.action_dim}",
            source,
        ) from e
    if (lo > hi).any() or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise ElicitError(f"invalid action bounds {lo.tolist()}..{hi.tolist()}", source)
    out = (demos.action < lo - 1e-6) | (demos.action > hi + 1e-6)
    if not out.any():
        return demos
    row, dim = (int(x) for x in np.argwhere(out)[0])
    msg = (
        f"action[{dim}] = {demos.action[row, dim]:.4g} outside bounds "
        f"[{lo[dim]:.4g}, {hi[dim]:.4g}] at {_where(demos, row)} "
        f"({int(out.any(axis=1).sum())} steps in all)"
    )
    if bounds == "error":
        raise ElicitError(msg + "; pass --clip-actions or --warn-actions to accept", source)
    if bounds == "warn":
        warnings.warn(f"{source}: {msg}", DemosWarning, stacklevel=3)
        return demos
    return dataclasses.replace(demos, action=np.clip(demos.action, lo, hi))
