"""A folder of several operators' sessions (``elicit-jax serve --sessions``, or any folder
whose subdirectories are sessions): list them, summarise them, merge their accepted
demonstrations into one demos artifact.

Hidden subdirectories (``.operators``, ``.removed``) are not sessions and are skipped; a
subdirectory without an ``artifact.json`` is not a session either.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from elicit_jax.errors import ElicitError


def session_dirs(root: str | Path) -> list[Path]:
    """The session directories directly under ``root``, by name."""
    root = Path(root)
    if not root.is_dir():
        return []
    return sorted(
        p
        for p in root.iterdir()
        if p.is_dir() and not p.name.startswith(".") and (p / "artifact.json").is_file()
    )


def is_sessions_folder(path: str | Path) -> bool:
    """A directory that is no artifact itself but holds at least one session."""
    path = Path(path)
    return path.is_dir() and not (path / "artifact.json").exists() and bool(session_dirs(path))


def session_summary(path: str | Path) -> dict[str, Any]:
    """One session's operator, settings and counts (from its episode files).

    Raises:
      ElicitError: ``path`` is no readable session.
    """
    from elicit_jax.elicit.config import SessionConfig
    from elicit_jax.elicit.progress import Progress, session_phase
    from elicit_jax.elicit.store import DEMOS_FILE, SessionStore

    store = SessionStore(path)
    header = store.header()
    config = SessionConfig.from_dict(header["config"])
    progress = Progress.load(store, config)
    c = progress.counts
    return {
        "name": Path(path).name,
        "operator": config.operator,
        "task": config.task,
        "mode": config.mode + (" + HG-DAgger" if config.dagger else ""),
        "phase": session_phase(config, progress),
        "counts": c,
        "last_verdict": str(progress.rows[-1].get("verdict", "")) if progress.rows else "",
        "demos": (Path(path) / DEMOS_FILE) if c.accepted else None,
    }


def merge_accepted(root: str | Path, out: str | Path, names: Sequence[str] | None = None) -> Any:
    """Write the accepted demonstrations of the sessions under ``root`` (all, or ``names``)
    into one demos artifact ``out``; episodes renumbered in operator order, each keeping its
    operator's label. Returns the written ``Demos``.

    Raises:
      ElicitError: no session has accepted demonstrations, or their files disagree.
    """
    from elicit_jax.data.demos import concat_demos, read_demos, write_demos

    root = Path(root)
    dirs = [d for d in session_dirs(root) if names is None or d.name in names]
    paths = [d / "demos.parquet" for d in dirs if session_summary(d)["demos"] is not None]
    if not paths:
        raise ElicitError("no session here has accepted demonstrations yet", root)
    parts = [read_demos(p) for p in paths]
    fields = [f.name for f in parts[0].obs_fields]
    for p, d in zip(paths, parts, strict=True):
        if d.task != parts[0].task or [f.name for f in d.obs_fields] != fields:
            raise ElicitError(f"holds {d.task} with other observation fields than {paths[0]}", p)
    merged = [p.parent.name for p in paths]
    provenance = {"source": "elicit-jax merged sessions", "sessions": merged, "root": str(root)}
    return write_demos(
        out,
        dataclasses.replace(concat_demos(parts, renumber=True), provenance=provenance),
        config={"merged_sessions": merged},
        inputs={p.parent.name: p for p in paths},
    )
