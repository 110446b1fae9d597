"""``elicit-jax demos``: list, select and concatenate demonstration artifacts."""

from __future__ import annotations

from pathlib import Path

import typer

from elicit_jax.cli.app import DATA, command_group
from elicit_jax.cli.outputs import OVERWRITE

demos_app = command_group(
    "demos", "List, select (subsets, splits) and concatenate demonstration files.", DATA
)

_EPISODES = "Episode ids and ranges, e.g. 0-4,7 (ids as `elicit-jax demos list` shows)."


def _print_episodes(demos: object, title: str, limit: int = 40) -> None:
    from rich.console import Console
    from rich.table import Table

    from elicit_jax.data.subsets import episode_table

    rows = episode_table(demos)
    table = Table(title=title, title_justify="left")
    for col in ("episode", "source episode", "operator", "steps", "success"):
        table.add_column(col, justify="left" if col in ("source episode", "operator") else "right")
    shown = rows if len(rows) <= limit else rows[: limit // 2] + rows[-limit // 2 :]
    for i, r in enumerate(shown):
        if len(rows) > limit and i == limit // 2:
            table.add_row("…", f"({len(rows) - limit} more)", "", "", "")
        table.add_row(
            str(r["episode"]),
            r["source_episode"],
            r["operator"],
            str(r["steps"]),
            "yes" if r["success"] else "no",
        )
    Console().print(table)


@demos_app.command("list")
def list_cmd(
    demos: Path = typer.Argument(..., help="A demos .parquet."),
    all_rows: bool = typer.Option(False, "--all", help="Every episode, not the first and last."),
) -> None:
    """List the episodes of a demos file: id, name in the source dataset, operator, steps.

    Example: elicit-jax demos list demos.parquet
    """
    from elicit_jax.data.demos import read_demos

    d = read_demos(demos, bounds="warn")
    _print_episodes(d, f"{demos}: {d.n_episodes} episodes", limit=10**9 if all_rows else 40)


@demos_app.command("select")
def select_cmd(
    demos: Path = typer.Argument(..., help="A demos .parquet."),
    out: Path = typer.Option(..., "-o", "--out", help="Demos .parquet to write."),
    episodes: str | None = typer.Option(None, "--episodes", help="Keep these. " + _EPISODES),
    exclude: str | None = typer.Option(None, "--exclude", help="Drop these. " + _EPISODES),
    operator: str | None = typer.Option(
        None, "--operator", help="Keep these operators (comma-separated)."
    ),
    source_episodes: str | None = typer.Option(
        None, "--source-episodes", help="Keep these source names, e.g. demo_3,demo_7."
    ),
    first: int | None = typer.Option(
        None, "--first", min=1, help="Keep only the first N of the episodes selected (id order)."
    ),
    drop_first: int | None = typer.Option(
        None, "--drop-first", min=0, help="Keep all but the first N of the episodes selected."
    ),
    overwrite: bool = OVERWRITE,
) -> None:
    """Write a subset of episodes; ids stay those of the input, source names are kept.

    A split is two selections: --episodes for one part, --exclude with the same ids for the
    other; or, whatever the order of the operators' demos, --first N and --drop-first N with
    the same --operator.

    Example: elicit-jax demos select demos.parquet --episodes 0-4 -o heldout.parquet

    Example: elicit-jax demos select demos.parquet --exclude 0-4 -o train.parquet

    Example: elicit-jax demos select demos.parquet --operator alice --first 3 -o heldout.parquet
    """
    from elicit_jax.artifact import check_outputs
    from elicit_jax.data.subsets import SubsetSpec, select_file

    check_outputs([out], [demos], overwrite=overwrite)
    spec = SubsetSpec(
        episodes=episodes,
        exclude=exclude,
        operators=operator,
        source_episodes=source_episodes,
        first=first,
        drop_first=drop_first,
    )
    d = select_file(demos, out, spec)
    _print_episodes(d, f"wrote {out}: {d.n_episodes} episodes, {d.n_steps} steps")


@demos_app.command("concat")
def concat_cmd(
    demos: list[Path] = typer.Argument(..., help="Two or more demos .parquet files, in order."),
    out: Path = typer.Option(..., "-o", "--out", help="Demos .parquet to write."),
    allow_duplicates: bool = typer.Option(
        False,
        "--allow-duplicates",
        help="Keep episodes identical (same observations and actions) to earlier ones.",
    ),
    overwrite: bool = OVERWRITE,
) -> None:
    """Concatenate demos files; episodes are renumbered 0..E-1 in input order.

    An episode identical to an earlier one (same observations and actions, e.g. overlapping
    files) is refused unless --allow-duplicates.

    The column `part` says which input each episode came from; `source_episode` still names
    it in its dataset.

    Example: elicit-jax demos concat base.parquet op2.parquet -o mixed.parquet
    """
    from elicit_jax.artifact import check_outputs
    from elicit_jax.data.subsets import concat_files

    check_outputs([out], demos, overwrite=overwrite)
    d = concat_files(demos, out, allow_duplicates=allow_duplicates)
    _print_episodes(d, f"wrote {out}: {d.n_episodes} episodes, {d.n_steps} steps")
