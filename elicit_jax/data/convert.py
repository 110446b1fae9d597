"""``elicit-jax import`` / ``export``: configs and the one library call behind each command."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import Any, Literal

from elicit_jax.artifact import make_header, read_header
from elicit_jax.data.demos import (
    BoundsPolicy,
    Demos,
    DemosWarning,
    read_demos,
    validate,
    write_demos,
)
from elicit_jax.data.selection import Selection, read_selection, write_episode_list
from elicit_jax.errors import ElicitError

Format = Literal["robomimic", "lerobot", "npz"]
FORMATS = ("robomimic", "lerobot", "npz")
EXPORT_KIND = "export"
EXPORT_SCHEMA_VERSION = 1


@dataclasses.dataclass(frozen=True)
class ImportConfig:
    """How to import a dataset into a demonstrations artifact.

    Attributes:
      source: the dataset file or folder.
      out: the demos ``.parquet`` to write.
      format: ``robomimic``, ``lerobot`` or ``npz``; ``None`` infers it from ``source``.
      obs_keys: observation keys (robomimic obs keys, LeRobot features); ``None``: defaults.
      operator: operator label (of every episode, or those no operator mask lists).
      operators_from_masks: robomimic only: glob of mask keys naming operators.
      filter_key: robomimic only: import the demos of ``mask/<filter_key>``.
      task: task name override.
      bounds: out-of-bounds actions: ``error``, ``warn`` or ``clip``.
      action_bounds: ``unit`` ([-1, 1]) or ``data`` (per-dim min/max); ``None``: the
        format's default (``unit`` for robomimic/npz, ``data`` for LeRobot).
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


def load_dataset(cfg: ImportConfig, progress: bool = False) -> Demos:
    """Read ``cfg.source`` into :class:`Demos` (action bounds not yet checked)."""
    fmt = cfg.format or infer_format(cfg.source)
    if fmt not in FORMATS:
        raise ElicitError(f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}")
    if fmt != "robomimic" and (cfg.operators_from_masks or cfg.filter_key):
        raise ElicitError("--operators-from-masks and --filter-key apply to robomimic files only")
    unit = (-1.0, 1.0)
    if fmt == "lerobot":
        from elicit_jax.data.lerobot import import_lerobot

        return import_lerobot(
            cfg.source,
            obs_keys=cfg.obs_keys,
            operator=cfg.operator,
            task=cfg.task,
            action_bounds=unit if cfg.action_bounds == "unit" else None,
        )
    if fmt == "robomimic":
        from elicit_jax.data.robomimic import import_robomimic

        demos = import_robomimic(
            cfg.source,
            obs_keys=cfg.obs_keys,
            operator=cfg.operator,
            operators_from_masks=cfg.operators_from_masks,
            filter_key=cfg.filter_key,
            task=cfg.task,
            action_bounds=unit,
            progress=progress,
        )
    else:
        from elicit_jax.data.npz import import_npz

        if cfg.obs_keys:
            raise ElicitError("--obs-keys does not apply to .npz files (one 'obs' array)")
        demos = import_npz(cfg.source, operator=cfg.operator, task=cfg.task, action_bounds=unit)
    return _data_bounds(demos, cfg.action_bounds)


def import_dataset(cfg: ImportConfig, progress: bool = False) -> Demos:
    """Import ``cfg.source`` and write the demonstrations artifact ``cfg.out``.

    Returns:
      The demonstrations as written (clipped if ``cfg.bounds == 'clip'``).
    """
    if Path(cfg.out).suffix != ".parquet":
        raise ElicitError("output must be a .parquet file", cfg.out)
    demos = load_dataset(cfg, progress=progress)
    config = {k: v for k, v in dataclasses.asdict(cfg).items() if k != "out"}
    demos = validate(demos, cfg.source, bounds=cfg.bounds)  # problems name the source file
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DemosWarning)  # already reported for the source
        return write_demos(
            cfg.out, demos, config=config, inputs={"source": cfg.source}, bounds=cfg.bounds
        )


@dataclasses.dataclass(frozen=True)
class ExportConfig:
    """How to export a selection of episodes back to a dataset format.

    Attributes:
      selection: a demos ``.parquet`` (its episodes are the selection) or an episode-list
        ``.json``.
      format: ``robomimic`` (a copy of the source with a new mask), ``lerobot`` (a new
        dataset folder, or an episode-list ``.json`` when ``out`` ends in ``.json``) or ``npz``.
      out: destination file or folder.
      episodes: narrow the selection to these episode ids.
      source: the original dataset; default the source recorded at import.
      mask_key: robomimic: the new filter key.
      overwrite: robomimic: replace an existing ``mask/<mask_key>``.
      version: LeRobot codebase version to write (``v2.1`` or ``v3.0``).
    """

    selection: str
    format: Format
    out: str
    episodes: tuple[int, ...] | None = None
    source: str | None = None
    mask_key: str | None = None
    overwrite: bool = False
    version: str = "v2.1"


def _source(cfg: ExportConfig, sel: Selection, importer: str) -> tuple[str, str | None]:
    """The original dataset and the sha256 it must have (``None``: unchecked)."""
    recorded = sel.provenance.get("importer")
    if recorded != importer:
        raise ElicitError(
            f"the selected demos were imported from {recorded or 'no dataset'}, not {importer}; "
            f"cannot map them back to a {importer} dataset",
            cfg.selection,
        )
    source = cfg.source or sel.provenance.get("source")
    if not source:
        raise ElicitError("no source dataset recorded; pass --source", cfg.selection)
    return str(source), sel.provenance.get("sha256")


def export_dataset(cfg: ExportConfig) -> dict[str, Any]:
    """Export the selected episodes; returns a summary (what was written where)."""
    sel = read_selection(cfg.selection, cfg.episodes)
    config = dataclasses.asdict(cfg)
    inputs = {"selection": cfg.selection}
    summary: dict[str, Any] = {"format": cfg.format, "out": cfg.out, "episodes": len(sel.episodes)}
    if cfg.format == "robomimic":
        from elicit_jax.data.robomimic import export_mask

        if not cfg.mask_key:
            raise ElicitError("robomimic export needs --mask-key (the new filter key)")
        source, sha = _source(cfg, sel, "robomimic")
        header = make_header(EXPORT_KIND, EXPORT_SCHEMA_VERSION, config=config, inputs=inputs)
        names = export_mask(
            source,
            cfg.out,
            cfg.mask_key,
            sel.source_episodes,
            overwrite=cfg.overwrite,
            expected_sha256=sha,
            header=header,
        )
        summary.update(source=source, mask_key=cfg.mask_key, demos=names)
    elif cfg.format == "lerobot" and Path(cfg.out).suffix == ".json":
        write_episode_list(cfg.out, sel, config=config, inputs=inputs)
        summary.update(source_episodes=list(sel.source_episodes))
    elif cfg.format == "lerobot":
        from elicit_jax.artifact import file_sha256
        from elicit_jax.data.lerobot_export import export_lerobot

        source, sha = _source(cfg, sel, "lerobot")
        if sha and file_sha256(source) != sha:
            raise ElicitError(
                "content differs from the dataset the demonstrations were imported from "
                "(sha256 mismatch); pass the original folder as --source",
                source,
            )
        header = make_header(EXPORT_KIND, EXPORT_SCHEMA_VERSION, config=config, inputs=inputs)
        written = export_lerobot(
            source,
            cfg.out,
            [int(n) for n in sel.source_episodes],
            version=cfg.version,
            header=header,
        )
        summary.update(source=source, version=cfg.version, source_episodes=written)
    elif cfg.format == "npz":
        from elicit_jax.data.npz import export_npz

        header = make_header(EXPORT_KIND, EXPORT_SCHEMA_VERSION, config=config, inputs=inputs)
        if read_header(cfg.selection).get("kind") != "demos":
            raise ElicitError(
                "npz export needs a demos .parquet, not an episode list", cfg.selection
            )
        demos = read_demos(cfg.selection, bounds="warn").select_episodes(sel.episodes)
        export_npz(demos, cfg.out, header=header)
        summary.update(steps=demos.n_steps)
    else:
        raise ElicitError(f"unknown format {cfg.format!r}; choose one of {', '.join(FORMATS)}")
    return summary
