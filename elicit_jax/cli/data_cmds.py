"""Data commands: import, export, info, make-example."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import typer

from elicit_jax.cli.app import DATA, HAND_BACK, INSPECT, app, check_seed
from elicit_jax.cli.outputs import OVERWRITE
from elicit_jax.errors import ElicitError


def _split(text: str | None) -> tuple[str, ...] | None:
    if not text:
        return None
    return tuple(k.strip() for k in text.split(",") if k.strip())


def _echo_warnings(fn: Callable[[], Any]) -> Any:
    """Run ``fn``; print data warnings as one ``warning:`` line each on stderr."""
    from elicit_jax.data.demos import DemosWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DemosWarning)
        result = fn()
    for w in caught:
        if issubclass(w.category, DemosWarning):
            typer.echo(f"warning: {w.message}", err=True)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return result


def _operator_table(path: Path) -> None:
    from rich.console import Console
    from rich.table import Table

    from elicit_jax.artifact import read_header
    from elicit_jax.cli.info_demos import operator_stats, success_recorded, success_text

    recorded = success_recorded(read_header(path))
    table = Table(title=f"wrote {path}", title_justify="left")
    for col in ("operator", "episodes", "steps", "length mean", "success"):
        table.add_column(col, justify="left" if col == "operator" else "right")
    for r in operator_stats(path):
        table.add_row(
            r["operator"],
            str(r["episodes"]),
            str(r["steps"]),
            f"{r['mean_length']:.1f}",
            success_text(r["success_rate"], recorded),
        )
    Console().print(table)


_FORMAT = typer.Option(
    None, "--format", "-f", help="robomimic | lerobot | npz (default: from the path)."
)
_OBS_KEYS = typer.Option(
    None,
    "--obs-keys",
    help="Comma-separated observation keys/features, in order (default: robomimic "
    "robot0_eef_pos,robot0_eef_quat,robot0_gripper_qpos,object; LeRobot observation.state).",
)
_OPERATOR = typer.Option("unknown", "--operator", help="Operator label of the demos.")
_OPERATORS_FROM_MASKS = typer.Option(
    None,
    "--operators-from-masks",
    help="robomimic: label each demo by the mask key matching this glob (or any of "
    "several, comma-separated) that lists it, e.g. '*_operator_*' or 'base,conflict'.",
)
_FILTER_KEY = typer.Option(
    None, "--filter-key", help="robomimic: import only the demos of mask/<KEY>."
)
_TASK = typer.Option(None, "--task", help="Task name (default: from the dataset).")
_CLIP = typer.Option(
    False, "--clip-actions", help="Clip actions outside their bounds instead of failing."
)
_WARN = typer.Option(False, "--warn-actions", help="Keep out-of-bounds actions, with a warning.")
_ACTION_BOUNDS = typer.Option(
    None,
    "--action-bounds",
    help="unit ([-1, 1]) or data (per-dim min/max). Default: unit for robomimic/npz, "
    "data for LeRobot.",
)
_SKIP_BAD = typer.Option(
    False,
    "--skip-bad-episodes",
    help="Leave out episodes with NaN/inf values (listed) instead of failing.",
)


def import_config(
    source: Path,
    out: Path | str,
    *,
    fmt: str | None,
    obs_keys: str | None,
    operator: str,
    operators_from_masks: str | None,
    filter_key: str | None,
    task: str | None,
    clip_actions: bool,
    warn_actions: bool,
    action_bounds: str | None,
    skip_bad_episodes: bool,
) -> Any:
    """The ``ImportConfig`` of ``import``'s options, checked the same way for every command
    that takes them (``import``, ``watch``)."""
    from elicit_jax.data.convert import ImportConfig

    if clip_actions and warn_actions:
        raise ElicitError("choose one of --clip-actions and --warn-actions")
    if action_bounds not in (None, "unit", "data"):
        raise ElicitError(f"--action-bounds must be 'unit' or 'data', not {action_bounds!r}")
    return ImportConfig(
        source=str(source),
        out=str(out),
        format=fmt,  # type: ignore[arg-type]
        obs_keys=_split(obs_keys),
        operator=operator,
        operators_from_masks=operators_from_masks,
        filter_key=filter_key,
        task=task,
        bounds="clip" if clip_actions else "warn" if warn_actions else "error",
        action_bounds=action_bounds,  # type: ignore[arg-type]
        skip_bad_episodes=skip_bad_episodes,
    )


@app.command("import", rich_help_panel=DATA)
def import_cmd(
    source: Path = typer.Argument(..., help="robomimic .hdf5, LeRobot folder or .npz."),
    out: Path = typer.Option(..., "-o", "--out", help="Demonstrations artifact to write."),
    fmt: str = _FORMAT,
    obs_keys: str = _OBS_KEYS,
    operator: str = _OPERATOR,
    operators_from_masks: str = _OPERATORS_FROM_MASKS,
    filter_key: str = _FILTER_KEY,
    task: str = _TASK,
    clip_actions: bool = _CLIP,
    warn_actions: bool = _WARN,
    action_bounds: str = _ACTION_BOUNDS,
    skip_bad_episodes: bool = _SKIP_BAD,
    overwrite: bool = OVERWRITE,
) -> None:
    """Import demonstrations from a robomimic, LeRobot or .npz dataset into a Parquet artifact.

    Example: elicit-jax import low_dim.hdf5 --format robomimic --operators-from-masks
    '*_operator_*' -o demos.parquet
    """
    from elicit_jax.artifact import check_outputs
    from elicit_jax.data.convert import import_dataset

    check_outputs([out], [source], overwrite=overwrite)
    cfg = import_config(
        source,
        out,
        fmt=fmt,
        obs_keys=obs_keys,
        operator=operator,
        operators_from_masks=operators_from_masks,
        filter_key=filter_key,
        task=task,
        clip_actions=clip_actions,
        warn_actions=warn_actions,
        action_bounds=action_bounds,
        skip_bad_episodes=skip_bad_episodes,
    )
    _echo_warnings(lambda: import_dataset(cfg, progress=_track))
    _operator_table(out)


def _track(items: Sequence[str], what: str) -> Iterable[str]:
    """A transient progress bar over ``items``."""
    from rich.progress import track

    return track(items, description=what, transient=True)


@app.command("export", rich_help_panel=HAND_BACK)
def export_cmd(
    selection: Path = typer.Argument(
        ..., help="Demos .parquet (its episodes are the selection) or an episode-list .json."
    ),
    fmt: str = typer.Option(..., "--format", "-f", help="robomimic | lerobot | npz."),
    out: Path = typer.Option(
        None,
        "-o",
        "--out",
        help="robomimic: the .hdf5 to write; lerobot: a new folder, or a .json episode list; "
        "npz: the .npz file.",
    ),
    episodes: str = typer.Option(
        None, "--episodes", help="Only these episode ids of the selection, e.g. 0,3,5-8."
    ),
    source: Path = typer.Option(
        None, "--source", help="Original dataset (default: the one recorded at import)."
    ),
    mask_key: str = typer.Option(
        None,
        "--mask-key",
        help="robomimic: mark the selected demos of the source file with this filter key "
        "(without it: write the demos as a new file).",
    ),
    in_place: bool = typer.Option(
        False,
        "--in-place",
        help="robomimic: add the mask to the source file itself instead of a copy (checks "
        "that nothing else in it changed; not atomic: keep a backup of files you cannot "
        "regenerate).",
    ),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace an existing output, or an existing mask/<KEY>."
    ),
    version: str = typer.Option(
        None,
        "--version",
        help="LeRobot codebase version: v3.0 (the default, also for a selection of a v2.1 "
        "dataset: LeRobot 0.4 and later read only v3.0) or v2.1 (LeRobot 0.1-0.3).",
    ),
    fresh: bool = typer.Option(
        False,
        "--fresh",
        help="lerobot: write the demos' own arrays as a new dataset even when they are whole "
        "episodes of a LeRobot dataset (whose cameras and other features are then not kept).",
    ),
    fps: float = typer.Option(
        None, "--fps", help="Frame rate of a new LeRobot dataset, when the demos do not tell it."
    ),
    valid_fraction: float = typer.Option(
        0.1, "--valid-fraction", help="New robomimic file: share of demos in mask/valid."
    ),
    seed: int = typer.Option(
        0, "--seed", help="Seed of the new robomimic file's train/valid split.", callback=check_seed
    ),
) -> None:
    """Export selected episodes to robomimic, LeRobot or .npz.

    robomimic: with --mask-key, a copy of the source file (or, with --in-place, the file
    itself) gets mask/KEY listing the selected demos; without it, a new file holds the demos.
    LeRobot: whole episodes of a LeRobot dataset are written as a selection of it (every
    feature kept); any other demos (collected, filtered pair by pair, from robomimic) as a
    new dataset; -o x.json writes an episode list for LeRobotDataset(episodes=...).

    Example: elicit-jax export kept.parquet --format robomimic --mask-key compatible
    -o low_dim_compatible.hdf5
    """
    from elicit_jax.data.export import ExportConfig, export_dataset
    from elicit_jax.data.selection import parse_episode_ids

    cfg = ExportConfig(
        selection=str(selection),
        format=fmt,  # type: ignore[arg-type]
        out=None if out is None else str(out),
        episodes=None if episodes is None else tuple(parse_episode_ids(episodes)),
        source=None if source is None else str(source),
        mask_key=mask_key,
        in_place=in_place,
        overwrite=overwrite,
        version=version,
        fresh=fresh,
        fps=fps,
        valid_fraction=valid_fraction,
        seed=seed,
    )
    if in_place:
        summary = _with_hash_progress(cfg, export_dataset)
    else:
        summary = _echo_warnings(lambda: export_dataset(cfg))
    _print_export(summary)


def _with_hash_progress(cfg: Any, export: Callable[..., dict]) -> dict:
    """Run an in-place export with a progress bar over the bytes it hashes (twice)."""
    from rich.progress import DownloadColumn, Progress, TextColumn

    from elicit_jax.data.selection import read_selection, single_source

    target = cfg.source
    if target is None:
        try:
            prov = single_source(read_selection(cfg.selection).provenance, cfg.selection)
            origin = prov.get("origin") or {}  # names restored across a LeRobot leg
            target = (origin if prov.get("importer") != "robomimic" and origin else prov)["source"]
        except ElicitError:  # export_dataset reports it, with what to do instead
            target = ""
    total = 2 * Path(target).stat().st_size if Path(target).is_file() else None
    with Progress(TextColumn("checking the file"), DownloadColumn(), transient=True) as bar:
        task = bar.add_task("hash", total=total)
        return _echo_warnings(lambda: export(cfg, progress=lambda n: bar.advance(task, n)))


def _print_export(summary: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.markup import escape

    console = Console(highlight=False, soft_wrap=True)  # commands stay copy-pastable
    mode = summary.get("mode", "")
    version = f" v{summary['version'].lstrip('v')}" if summary.get("version") else ""
    console.print(
        f"wrote {summary['out']} ({summary['format']}{version}, {mode}): "
        f"{summary['episodes']} episodes"
    )
    if "mask_key" in summary:
        where = " in place (nothing else in the file changed)" if summary["in_place"] else ""
        console.print(
            f"robomimic filter key '{summary['mask_key']}' lists {len(summary['demos'])} demos"
            f"{where}; train with config.train.data={summary['out']} "
            f"config.train.hdf5_filter_key={summary['mask_key']}"
        )
    if summary.get("masks"):
        console.print(
            "masks: " + ", ".join(f"{k} ({v} demos)" for k, v in summary["masks"].items())
        )
        console.print(
            f"robomimic: config.train.data={summary['out']} "
            f"config.observation.modalities.obs.low_dim={summary['obs_keys']}"
        )
    if summary.get("cameras"):
        console.print(
            f"camera statistics carried from the source: {', '.join(summary['cameras'])}; "
            f"video files copied: {summary['videos']}"
        )
    if "load" in summary:
        console.print(
            "load in LeRobot: import json; from lerobot.datasets.lerobot_dataset import "
            f"LeRobotDataset; ds = {summary['load']}"
        )
    for note in summary.get("notes", []):
        console.print(f"note: {escape(note)}")
    if "reimport" in summary:
        console.print(f"read back: {summary['reimport']}")


@app.command(rich_help_panel=INSPECT)
def info(
    artifact: Path = typer.Argument(
        ..., help="Any elicit-jax artifact, or a raw robomimic .hdf5 / LeRobot folder."
    ),
) -> None:
    """Describe an artifact: its kind, schema version, shapes and provenance.

    Example: elicit-jax info demos.parquet
    """
    from elicit_jax.cli.info import describe

    describe(artifact)


@app.command("make-example", rich_help_panel=DATA)
def make_example(
    out: Path = typer.Option(Path("example.hdf5"), "-o", "--out", help="HDF5 file to write."),
    demos_per_operator: int = typer.Option(25, "--demos-per-operator", min=1),
    seed: int = typer.Option(0, "--seed", callback=check_seed),
    overwrite: bool = OVERWRITE,
) -> None:
    """Generate a SYNTHETIC toy dataset (2-D point reaching, two operator styles) in
    robomimic's HDF5 layout, to try the tool without downloading anything.

    Example: elicit-jax make-example -o example.hdf5
    """
    from elicit_jax.artifact import check_outputs
    from elicit_jax.data.synthetic import ToyConfig, make_toy_robomimic

    check_outputs([out], overwrite=overwrite)
    counts = make_toy_robomimic(out, ToyConfig(demos_per_operator=demos_per_operator, seed=seed))
    typer.echo(
        f"wrote {out}: synthetic toy 2-D reaching task (not robot data), "
        + ", ".join(f"{k}: {v} demos" for k, v in counts.items())
    )
    typer.echo(
        f"next: elicit-jax import {out} --format robomimic --obs-keys agent_pos,goal_pos "
        "--operators-from-masks '*_operator_*' -o demos.parquet"
    )
