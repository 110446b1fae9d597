"""``elicit-jax info``: describe any artifact by its header's ``kind``.

Each artifact kind registers a describer with :func:`register`; unknown kinds fall back to
printing the header.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from elicit_jax.artifact import read_header

Describer = Callable[[Path, dict[str, Any]], None]
_DESCRIBERS: dict[str, Describer] = {}


def register(kind: str) -> Callable[[Describer], Describer]:
    """Decorator registering ``fn(path, header)`` as the describer of ``kind``."""

    def deco(fn: Describer) -> Describer:
        _DESCRIBERS[kind] = fn
        return fn

    return deco


def _load_describers() -> None:
    import importlib

    for mod in (
        "elicit_jax.data.describe_demos",
        "elicit_jax.compat.describe_compat",
        "elicit_jax.sim.describe_rollouts",
        "elicit_jax.policy.describe_checkpoint",
    ):
        try:
            importlib.import_module(mod)
        except ModuleNotFoundError as e:
            if e.name != mod:
                raise


def _describe_raw_source(path: Path) -> bool:
    """Describe a not-yet-imported robomimic file or LeRobot folder; False if neither."""
    if path.is_file() and path.suffix.lower() in (".hdf5", ".h5", ".he5"):
        from elicit_jax.data.describe_demos import describe_robomimic_file

        describe_robomimic_file(path)
        return True
    if (
        path.is_dir()
        and not (path / "artifact.json").exists()
        and (path / "meta/info.json").exists()
    ):
        from elicit_jax.data.describe_demos import describe_lerobot_folder

        describe_lerobot_folder(path)
        return True
    return False


def _short(value: Any, limit: int = 160) -> str:
    from elicit_jax.artifact import dumps

    text = value if isinstance(value, str) else " ".join(dumps(value).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def describe(path: str | Path) -> None:
    """Print a description of the artifact at ``path``.

    Known kinds use their registered describer; raw robomimic files and LeRobot folders get a
    summary of what an import would see; any other artifact lists its header fields.
    """
    from rich.console import Console
    from rich.table import Table

    path = Path(path)
    if _describe_raw_source(path):
        return
    header = read_header(path)
    _load_describers()
    fn = _DESCRIBERS.get(header.get("kind", ""))
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
