"""The session directory: created, or checked against the settings and inputs it was made with.

:func:`open_store` creates the directory of a new session or resumes the one there. A
directory holding another kind of artifact, or a session started with other settings or
other input files, is refused with one line saying what differs (``--overwrite`` starts that
session again; it never replaces anything but a session). Inputs inside the session
directory, or an output that would overwrite an input, are refused too.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from elicit_jax.artifact import matches_recorded, refuse_overwriting_inputs
from elicit_jax.elicit.config import SessionConfig
from elicit_jax.elicit.store import SessionStore
from elicit_jax.errors import ElicitError


def absolute_inputs(config: SessionConfig) -> SessionConfig:
    """The config with its input paths made absolute (a session resumes from anywhere)."""
    return config.with_absolute_paths()


def session_inputs(config: SessionConfig) -> dict[str, str]:
    """The session's input files by role (their hashes go in the session's header)."""
    out = {"policy": config.policy, "base_demos": config.base_demos}
    if config.thresholds.file is not None:
        out["thresholds"] = str(config.thresholds.file)
    return out


def open_store(
    root: Path,
    config: SessionConfig,
    inputs: dict[str, str],
    header: dict[str, Any],
    overwrite: bool,
) -> tuple[SessionStore, bool]:
    """Create the session directory or check the one there; returns (store, resumed)."""
    store = SessionStore(root)
    if root.exists() and not root.is_dir():
        raise ElicitError("is a file, not a session directory", root)
    for name, p in inputs.items():
        if Path(p).resolve().is_relative_to(root.resolve()):
            raise ElicitError(f"the {name} input lies inside the session directory", p)
    refuse_overwriting_inputs([root], inputs.values())
    if root.is_dir() and any(root.iterdir()):
        try:
            old = store.header()
        except ElicitError as e:
            why = str(e).removeprefix(f"{e.path}: ") if e.path else str(e)
            raise ElicitError(
                f"holds no elicitation session ({why}); choose another output directory", root
            ) from e
        diffs = config.differences(SessionConfig.from_dict(old.get("config", {})))
        recorded = old.get("inputs", {})
        diffs += [
            f"{k} file"
            for k, p in inputs.items()
            if not matches_recorded(recorded.get(k, {}).get("sha256"), p)
        ]
        if not overwrite and diffs:
            raise ElicitError(
                f"holds a session with different settings ({', '.join(diffs)}); re-run with its "
                "settings to resume it, or pass --overwrite to start it again",
                root,
            )
        if not overwrite:
            store.clean_temporaries()
            if old.get("config") != header["config"]:  # more demos or episodes asked for
                store.create({**old, "config": header["config"]})
            return store, True
        store.wipe()
    store.create(header)
    return store, False
