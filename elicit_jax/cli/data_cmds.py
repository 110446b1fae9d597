"""Data commands: import, export, info, make-example."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import typer

from elicit_jax.cli.app import app
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

    from elicit_jax.data.describe_demos import operator_stats

    table = Table(title=f"wrote {path}", title_justify="left")
    for col in ("operator", "episodes", "steps", "length mean", "success"):
        table.add_column(col, justify="left" if col == "operator" else "right")
    for r in operator_stats(path):
        table.add_row(
            r["operator"],
            str(r["episodes"]),
            str(r["steps"]),
            f"{r['mean_length']:.1f}",
            f"{100 * r['success_rate']:.0f}%",
        )
    Console().print(table)


@app.command("import")
def import_cmd(
    source: Path = typer.Argument(..., help="robomimic .hdf5, LeRobot folder or .npz."),
    out: Path = typer.Option(..., "-o", "--out", help="Demonstrations artifact to write."),
    fmt: str = typer.Option(
        None, "--format", "-f", help="robomimic | lerobot | npz (default: from the path)."
    ),
    obs_keys: str = typer.Option(
        None,
        "--obs-keys",
        help="Comma-separated observation keys/features, in order (default: robomimic "
        "robot0_eef_pos,robot0_eef_quat,robot0_gripper_qpos,object; LeRobot observation.state).",
    ),
    operator: str = typer.Option("unknown", "--operator", help="Operator label of the demos."),
    operators_from_masks: str = typer.Option(
        None,
        "--operators-from-masks",
        help="robomimic: label each demo by the mask key matching this glob that lists it, "
        "e.g. '*_operator_*'.",
    ),
    filter_key: str = typer.Option(
        None, "--filter-key", help="robomimic: import only the demos of mask/<KEY>."
    ),
    task: str = typer.Option(None, "--task", help="Task name (default: from the dataset)."),
    clip_actions: bool = typer.Option(
        False, "--clip-actions", help="Clip actions outside their bounds instead of failing."
    ),
    warn_actions: bool = typer.Option(
        False, "--warn-actions", help="Keep out-of-bounds actions, with a warning."
    ),
    action_bounds: str = typer.Option(
        None,
        "--action-bounds",
        help="unit ([-1, 1]) or data (per-dim min/max). Default: unit for robomimic/npz, "
        "data for LeRobot.",
    ),
) -> None:
    """Import demonstrations from a robomimic, LeRobot or .npz dataset into a Parquet artifact.

    Example: elicit-jax import low_dim.hdf5 --format robomimic --operators-from-masks
    '*_operator_*' -o demos.parquet
    """
    from elicit_jax.data.convert import ImportConfig, import_dataset

    if clip_actions and warn_actions:
        raise ElicitError("choose one of --clip-actions and --warn-actions")
    if action_bounds not in (None, "unit", "data"):
        raise ElicitError(f"--action-bounds must be 'unit' or 'data', not {action_bounds!r}")
    cfg = ImportConfig(
        source=str(source),
        out=str(out),
        format=fmt,
        obs_keys=_split(obs_keys),
        operator=operator,
        operators_from_masks=operators_from_masks,
        filter_key=filter_key,
        task=task,
        bounds="clip" if clip_actions else "warn" if warn_actions else "error",
        action_bounds=action_bounds,
    )
    _echo_warnings(lambda: import_dataset(cfg, progress=True))
    _operator_table(out)


@app.command("export")
def export_cmd(
    selection: Path = typer.Argument(
        ..., help="Demos .parquet (its episodes are the selection) or an episode-list .json."
    ),
    fmt: str = typer.Option(..., "--format", "-f", help="robomimic | lerobot | npz."),
    out: Path = typer.Option(
        ...,
        "-o",
        "--out",
        help="robomimic: the .hdf5 copy; lerobot: a new folder, or a .json episode list; "
        "npz: the .npz file.",
    ),
    episodes: str = typer.Option(
        None, "--episodes", help="Only these episode ids of the selection, e.g. 0,3,5-8."
    ),
    source: Path = typer.Option(
        None, "--source", help="Original dataset (default: the one recorded at import)."
    ),
    mask_key: str = typer.Option(None, "--mask-key", help="robomimic: the new filter key."),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="robomimic: replace an existing mask/<KEY>."
    ),
    version: str = typer.Option("v2.1", "--version", help="LeRobot codebase version: v2.1|v3.0."),
) -> None:
    """Export selected episodes back to their dataset format.

    Example: elicit-jax export kept.parquet --format robomimic --source low_dim.hdf5
    --mask-key compatible -o low_dim_compatible.hdf5
    """
    from rich.console import Console

    from elicit_jax.data.convert import ExportConfig, export_dataset
    from elicit_jax.data.selection import parse_episode_ids

    cfg = ExportConfig(
        selection=str(selection),
        format=fmt,
        out=str(out),
        episodes=None if episodes is None else tuple(parse_episode_ids(episodes)),
        source=None if source is None else str(source),
        mask_key=mask_key,
        overwrite=overwrite,
        version=version,
    )
    summary = _echo_warnings(lambda: export_dataset(cfg))
    console = Console()
    console.print(f"wrote {summary['out']} ({summary['format']}): {summary['episodes']} episodes")
    if "mask_key" in summary:
        console.print(
            f"robomimic filter key '{summary['mask_key']}' lists {len(summary['demos'])} demos; "
            f"train with config.train.data={summary['out']} "
            f"config.train.hdf5_filter_key={summary['mask_key']}"
        )


@app.command()
def info(
    artifact: Path = typer.Argument(
        ..., help="Any elicit-jax artifact, or a raw robomimic .hdf5 / LeRobot folder."
    ),
) -> None:
    """Describe an artifact: its kind, schema version, shapes and provenance.

    Example: elicit-jax info demos.parquet
    """
    from elicit_jax.describe import describe

    describe(artifact)


@app.command("make-example")
def make_example(
    out: Path = typer.Option(Path("example.hdf5"), "-o", "--out", help="HDF5 file to write."),
    demos_per_operator: int = typer.Option(25, "--demos-per-operator", min=1),
    seed: int = typer.Option(0, "--seed"),
) -> None:
    """Generate a SYNTHETIC toy dataset (2-D point reaching, two operator styles) in
    robomimic's HDF5 layout, to try the tool without downloading anything.

    Example: elicit-jax make-example -o example.hdf5
    """
    from elicit_jax.data.synthetic import ToyConfig, make_toy_robomimic

    counts = make_toy_robomimic(out, ToyConfig(demos_per_operator=demos_per_operator, seed=seed))
    typer.echo(
        f"wrote {out}: synthetic toy 2-D reaching task (not robot data), "
        + ", ".join(f"{k}: {v} demos" for k, v in counts.items())
    )
    typer.echo(
        f"next: elicit-jax import {out} --format robomimic --obs-keys agent_pos,goal_pos "
        "--operators-from-masks '*_operator_*' -o demos.parquet"
    )
