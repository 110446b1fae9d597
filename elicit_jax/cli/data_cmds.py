"""Data commands: import, export, info, make-example."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import typer

from elicit_jax.cli import data_options as do
from elicit_jax.cli.app import DATA, HAND_BACK, INSPECT, app, check_seed
from elicit_jax.cli.outputs import OVERWRITE
from elicit_jax.cli.params import with_flags
from elicit_jax.errors import ElicitError


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

    from elicit_jax.artifact import read_header
    from elicit_jax.cli.info_demos import operator_table

    Console().print(operator_table(path, read_header(path), f"wrote {path}", spread=False))


@app.command("import", rich_help_panel=DATA)
@with_flags(do.IMPORT_FLAGS, before="overwrite")
def import_cmd(
    ctx: typer.Context,
    source: Path = typer.Argument(..., help="robomimic .hdf5, LeRobot folder or .npz."),
    out: Path = typer.Option(..., "-o", "--out", help="Demonstrations artifact to write."),
    overwrite: bool = OVERWRITE,
    **flags: Any,
) -> None:
    """Import demonstrations from a robomimic, LeRobot or .npz dataset into a Parquet artifact.

    Example: elicit-jax import low_dim.hdf5 --format robomimic --operators-from-masks
    '*_operator_*' -o demos.parquet
    """
    from elicit_jax.artifact import check_outputs
    from elicit_jax.data.convert import import_dataset

    check_outputs([out], [source], overwrite=overwrite)
    cfg = do.import_config(source, out, ctx.params)
    _echo_warnings(lambda: import_dataset(cfg, progress=_track))
    _operator_table(out)


def _track(items: Sequence[str], what: str) -> Iterable[str]:
    """A transient progress bar over ``items``."""
    from rich.progress import track

    return track(items, description=what, transient=True)


@app.command("export", rich_help_panel=HAND_BACK)
def export_cmd(
    ctx: typer.Context,
    selection: Path = typer.Argument(
        ..., help="Demos .parquet (its episodes are the selection) or an episode-list .json."
    ),
    fmt: str = typer.Option(..., "--format", "-f", help="robomimic | lerobot | npz."),
    out: Path = do.EXPORT_OUT,
    episodes: str = do.EPISODES,
    source: Path = do.EXPORT_SOURCE,
    mask_key: str = do.MASK_KEY,
    in_place: bool = do.IN_PLACE,
    overwrite: bool = do.EXPORT_OVERWRITE,
    version: str = do.VERSION,
    fresh: bool = do.FRESH,
    fps: float = do.FPS,
    valid_fraction: float = do.VALID_FRACTION,
    seed: int = do.EXPORT_SEED,
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
    from elicit_jax.data.export import export_dataset

    cfg = do.export_config(selection, ctx.params)
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
