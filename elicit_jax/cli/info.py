"""``elicit-jax info``: describe any artifact by its header's ``kind``.

Each artifact kind maps to a describer ``fn(path, header)`` in a ``cli/info_*`` module
(:data:`DESCRIBERS`), imported only when needed, so describers never import this module (no
import cycle); unknown kinds fall back to printing the header. Describers print; the library
layers they read from do not.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import read_header

Describer = Callable[[Path, dict[str, Any]], None]

# kind -> (module, function) of its describer.
DESCRIBERS: dict[str, tuple[str, str]] = {
    "demos": ("elicit_jax.cli.info_demos", "describe_demos"),
    "episode-list": ("elicit_jax.cli.info_demos", "describe_episode_list"),
    "export": ("elicit_jax.cli.info_demos", "describe_export"),
    "scores": ("elicit_jax.cli.info_compat", "describe_scores"),
    "episode-scores": ("elicit_jax.cli.info_compat", "describe_episode_scores"),
    "thresholds": ("elicit_jax.cli.info_compat", "describe_thresholds"),
    "filter-log": ("elicit_jax.cli.info_compat", "describe_filter_log"),
    "rollouts": ("elicit_jax.cli.info_rollouts", "describe_rollouts"),
    "checkpoint": ("elicit_jax.cli.info_checkpoint", "describe_run"),
    "training_run": ("elicit_jax.cli.info_checkpoint", "describe_run"),
    "elicit-session": ("elicit_jax.cli.info_session", "describe_session"),
}


def describer(kind: str) -> Describer | None:
    """The describer of an artifact ``kind``, or ``None`` for kinds without one."""
    if kind not in DESCRIBERS:
        return None
    module, name = DESCRIBERS[kind]
    return getattr(importlib.import_module(module), name)


def describe_curation_scores(path: Path, header: dict[str, Any]) -> None:
    """Per-operator summary of a curation method's per-demonstration scores (``filter
    --method deminf|demo-score|cupid|quality``'s ``OUT.episode-scores.parquet``), which share
    the kind ``episode-scores`` with ``score``'s per-episode summary."""
    from rich.console import Console
    from rich.table import Table

    from elicit_jax.curation.episodes import read_episode_scores

    scores = read_episode_scores(path)
    cut = scores.threshold
    table = Table(
        title=f"{path.name}: {scores.method} scores per operator (higher = keep"
        + (f"; dropped at <= {cut:.4g})" if cut is not None else ")")
    )
    for col in ("operator", "episodes", "score min", "score mean", "score max", "at or below cut"):
        table.add_column(col, justify="left" if col == "operator" else "right")
    ops = np.asarray(scores.operator).astype(str)
    for op in sorted(set(ops.tolist())):
        s = np.asarray(scores.score, float)[ops == op]
        low = "-" if cut is None else str(int((s <= cut).sum()))
        stats = (f"{v + 0.0:.4g}" for v in (s.min(), s.mean(), s.max()))  # + 0.0: no "-0"
        table.add_row(op, str(len(s)), *stats, low)
    console = Console()
    console.print(table)
    if not scores.trusted:
        why = scores.report.get("why", "no signal to rank with")
        console.print(f"[bold red]not trustworthy[/]: {why}")


def _describe_raw_source(path: Path) -> bool:
    """Describe a not-yet-imported robomimic file or LeRobot folder; False if neither."""
    if path.is_file() and path.suffix.lower() in (".hdf5", ".h5", ".he5"):
        from elicit_jax.cli.info_demos import describe_robomimic_file

        describe_robomimic_file(path)
        return True
    if (
        path.is_dir()
        and not (path / "artifact.json").exists()
        and (path / "meta/info.json").exists()
    ):
        from elicit_jax.cli.info_demos import describe_lerobot_folder

        describe_lerobot_folder(path)
        return True
    return False


def _short(value: Any, limit: int = 160) -> str:
    from elicit_jax.artifact import dumps

    text = value if isinstance(value, str) else " ".join(dumps(value).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def describe(path: str | Path) -> None:
    """Print a description of the artifact at ``path``.

    Known kinds use their describer (:data:`DESCRIBERS`); raw robomimic files and LeRobot
    folders get a summary of what an import would see; any other artifact lists its header
    fields; a folder of operators' sessions gets one row per operator.
    """
    from rich.console import Console
    from rich.table import Table

    path = Path(path)
    if _describe_raw_source(path):
        return
    from elicit_jax.cli.info_session import describe_sessions_folder
    from elicit_jax.elicit.sessions_folder import is_sessions_folder

    if is_sessions_folder(path):
        describe_sessions_folder(path)
        return
    if path.is_dir() and not (path / "artifact.json").exists():
        from elicit_jax.errors import ElicitError

        raise ElicitError(
            "holds no elicit-jax artifact (no artifact.json), LeRobot dataset (no meta/info.json) "
            "or operator session (a sessions folder has none until an operator starts)",
            path,
        )
    header = read_header(path)
    fn = describer(str(header.get("kind", "")))
    if header.get("kind") == "episode-scores" and "method" in header:
        fn = describe_curation_scores
    if fn is not None:
        fn(path, header)
        return
    console = Console()
    console.print(
        f"[bold]{path}[/]: {header.get('kind', '?')} (schema v{header.get('schema_version', '?')})"
    )
    table = Table(show_header=False)
    table.add_column(style="bold")
    table.add_column(overflow="fold")
    for key in sorted(header):
        if key == "inputs":
            for name, item in header[key].items():
                sha = str(item.get("sha256", ""))[:12] if isinstance(item, dict) else ""
                where = item.get("path") if isinstance(item, dict) else item
                table.add_row(f"input {name}", f"{where} (sha256 {sha}...)")
        elif key not in ("kind", "schema_version"):
            table.add_row(key, _short(header[key]))
    console.print(table)
