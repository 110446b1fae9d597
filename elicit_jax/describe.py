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

    for mod in ("elicit_jax.data.describe_demos",):
        try:
            importlib.import_module(mod)
        except ModuleNotFoundError as e:
            if e.name != mod:
                raise


def describe(path: str | Path) -> None:
    """Print a description of the artifact at ``path``."""
    from rich.console import Console

    path = Path(path)
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
    for key in sorted(header):
        if key not in ("kind", "schema_version"):
            console.print(f"  {key}: {header[key]}")
