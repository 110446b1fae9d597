"""``elicit-jax import``: its config and the one library call behind it (export:
:mod:`elicit_jax.data.export`)."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

from elicit_jax.artifact import refuse_overwriting_inputs
from elicit_jax.data.demos import (
    SOURCE_EPISODE,
    BoundsPolicy,
    Demos,
    DemosWarning,
    validate,
    write_demos,
)
from elicit_jax.data.validation import action_dim_warnings, bad_episodes, check_operator_name
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.data.robomimic import Progress

Format = Literal["robomimic", "lerobot", "npz"]
FORMATS = ("robomimic", "lerobot", "npz")


@dataclasses.dataclass(frozen=True)
class ImportConfig:
    """How to import a dataset into a demonstrations artifact.

    Attributes:
      source: the dataset file or folder.
      out: the demos ``.parquet`` to write.
      format: ``robomimic``, ``lerobot`` or ``npz``; ``None`` infers it from ``source``.
      obs_keys: observation keys (robomimic obs keys, LeRobot features); ``None``: defaults.
      operator: operator label (of every episode, or those no operator mask lists).
      operators_from_masks: robomimic only: glob of mask keys naming operators, or several
        comma-separated.
      filter_key: robomimic only: import the demos of ``mask/<filter_key>``.
      task: task name override.
      bounds: out-of-bounds actions: ``error``, ``warn`` or ``clip``.
      action_bounds: ``unit`` ([-1, 1]) or ``data`` (per-dim min/max); ``None``: the
        format's default (``unit`` for robomimic/npz, ``data`` for LeRobot).
      skip_bad_episodes: leave out episodes with non-finite values (listed in a warning and
        in the provenance) instead of failing.
      allow_duplicates: keep episodes identical (obs and actions, step for step) to an earlier
        episode of the same source, with a warning; without it they are refused.
    """

    source: str
    out: str
    format: Format | None = None
    obs_keys: tuple[str, ...] | None = None
    operator: str = "unknown"
    operators_from_masks: str | None = None
    filter_key: str | None = None
    task: str | None = None
    bounds: BoundsPolicy = "error"
    action_bounds: Literal["unit", "data"] | None = None
    skip_bad_episodes: bool = False
    allow_duplicates: bool = False

    def __post_init__(self) -> None:
        check_operator_name(self.operator, "--operator")


def infer_format(source: str | Path) -> Format:
    """Guess a dataset's format from its path."""
    source = Path(source)
    if not source.exists():
        raise ElicitError("file not found", source)
    if source.is_dir():
        if (source / "meta" / "info.json").is_file():
            return "lerobot"
        raise ElicitError("folder is not a LeRobot dataset (no meta/info.json)", source)
    suffix = source.suffix.lower()
    if suffix in (".hdf5", ".h5", ".he5"):
        return "robomimic"
    if suffix == ".npz":
        return "npz"
    raise ElicitError(
        f"unknown dataset format '{suffix}'; pass --format {'|'.join(FORMATS)}", source
    )


def _data_bounds(demos: Demos, mode: str | None) -> Demos:
    if mode != "data":
        return demos
    return dataclasses.replace(
        demos,
        action_low=tuple(demos.action.min(0).tolist()),
        action_high=tuple(demos.action.max(0).tolist()),
        provenance={**demos.provenance, "action_bounds_from": "data min/max"},
    )


def load_dataset(cfg: ImportConfig, progress: Progress | None = None) -> Demos:
    """Read ``cfg.source`` into :class:`Demos` (action bounds not yet checked); ``progress``
    wraps the episodes read (robomimic files; see :data:`~elicit_jax.data.robomimic.Progress`)."""
    fmt = cfg.format or infer_format(cfg.source)
    if fmt not in FORMATS:
        raise ElicitError(f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}")
    if fmt != "robomimic" and (cfg.operators_from_masks or cfg.filter_key):
        raise ElicitError("--operators-from-masks and --filter-key apply to robomimic files only")
    unit = (-1.0, 1.0)
    # what every importer takes; an .npz file has one 'obs' array, so no obs keys
    common = {"operator": cfg.operator, "task": cfg.task, "finite": not cfg.skip_bad_episodes}
    if fmt == "lerobot":
        from elicit_jax.data.lerobot import import_lerobot

        bounds = unit if cfg.action_bounds == "unit" else None
        demos = import_lerobot(cfg.source, obs_keys=cfg.obs_keys, action_bounds=bounds, **common)
        demos = _skip_bad(demos, cfg.source) if cfg.skip_bad_episodes else demos
        _check_duplicates(demos, cfg)
        return demos
    if fmt == "robomimic":
        from elicit_jax.data.robomimic import import_robomimic

        demos = import_robomimic(
            cfg.source,
            obs_keys=cfg.obs_keys,
            operators_from_masks=cfg.operators_from_masks,
            filter_key=cfg.filter_key,
            action_bounds=unit,
            progress=progress,
            **common,
        )
    else:
        from elicit_jax.data.npz import import_npz

        if cfg.obs_keys:
            raise ElicitError("--obs-keys does not apply to .npz files (one 'obs' array)")
        demos = import_npz(cfg.source, action_bounds=unit, **common)
    if cfg.skip_bad_episodes:
        demos = _skip_bad(demos, cfg.source)
    _check_duplicates(demos, cfg)
    return _data_bounds(demos, cfg.action_bounds)


def _check_duplicates(demos: Demos, cfg: ImportConfig) -> None:
    """Refuse (or, with ``cfg.allow_duplicates``, warn about) episodes of one source that
    repeat an earlier one step for step: trained on twice, and exported twice."""
    from elicit_jax.data.duplicates import find_duplicates

    dups = find_duplicates([demos])
    if not dups:
        return
    names = demos.extra.get(SOURCE_EPISODE)
    first = {e: s for e, s, _ in demos.episode_bounds()}

    def name(e: int) -> str:
        return f"episode {e}" + (f" ({names[first[e]]})" if names is not None else "")

    shown = "; ".join(f"{name(d.episode)} repeats {name(d.of_episode)}" for d in dups[:3])
    more = f" (and {len(dups) - 3} more)" if len(dups) > 3 else ""
    msg = f"{len(dups)} episode(s) repeat earlier ones step for step: {shown}{more}"
    if not cfg.allow_duplicates:
        raise ElicitError(f"{msg}; pass --allow-duplicates to keep them", cfg.source)
    warnings.warn(f"{cfg.source}: {msg} (kept: --allow-duplicates)", DemosWarning, stacklevel=3)


def import_dataset(cfg: ImportConfig, progress: Progress | None = None) -> Demos:
    """Import ``cfg.source`` and write the demonstrations artifact ``cfg.out``.

    Returns:
      The demonstrations as written (clipped if ``cfg.bounds == 'clip'``).
    """
    if Path(cfg.out).suffix != ".parquet":
        raise ElicitError("output must be a .parquet file", cfg.out)
    refuse_overwriting_inputs([cfg.out], [cfg.source])
    demos = load_dataset(cfg, progress=progress)
    config = {k: v for k, v in dataclasses.asdict(cfg).items() if k != "out"}
    demos = validate(demos, cfg.source, bounds=cfg.bounds)  # problems name the source file
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DemosWarning)  # already reported for the source
        demos = write_demos(
            cfg.out, demos, config=config, inputs={"source": cfg.source}, bounds=cfg.bounds
        )
    for msg in action_dim_warnings(demos.action):
        warnings.warn(f"{cfg.source}: {msg}", DemosWarning, stacklevel=2)
    return demos


def _skip_bad(demos: Demos, source: str) -> Demos:
    """``demos`` without the episodes :func:`bad_episodes` finds; each is named in a warning
    and recorded in the provenance (``skipped_episodes``)."""
    bad = bad_episodes(demos)
    if not bad:
        return demos
    if len(bad) == demos.n_episodes:
        raise ElicitError(
            f"every one of the {len(bad)} episodes has non-finite or absurd values", source
        )
    names = demos.extra.get(SOURCE_EPISODE)
    first = {e: s for e, s, _ in demos.episode_bounds()}
    skipped = [
        {"episode": e, "source_episode": str(names[first[e]]) if names is not None else str(e),
         "reason": why}
        for e, why in sorted(bad.items())
    ]  # fmt: skip
    listed = "; ".join(f"{s['source_episode']}: {s['reason']}" for s in skipped)
    warnings.warn(
        f"{source}: skipped {len(skipped)} of {demos.n_episodes} episodes ({listed})",
        DemosWarning,
        stacklevel=3,
    )
    kept = demos.select(~np.isin(demos.episode, list(bad)))
    return dataclasses.replace(kept, provenance={**kept.provenance, "skipped_episodes": skipped})
