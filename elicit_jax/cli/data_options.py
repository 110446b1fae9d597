"""The flags of ``import`` (which ``watch`` shares: it imports what lands in its folder) and
of ``export``, and the configs they build.

Declared once, so every command that reads a dataset spells, documents and checks them the
same way.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from elicit_jax.cli.app import check_seed
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.data.convert import ImportConfig
    from elicit_jax.data.export_config import ExportConfig

FORMAT = typer.Option(
    None, "--format", "-f", help="robomimic | lerobot | npz (default: from the path)."
)
OBS_KEYS = typer.Option(
    None,
    "--obs-keys",
    help="Comma-separated observation keys/features, in order (default: robomimic "
    "robot0_eef_pos,robot0_eef_quat,robot0_gripper_qpos,object; LeRobot observation.state).",
)
OPERATOR = typer.Option("unknown", "--operator", help="Operator label of the demos.")
OPERATORS_FROM_MASKS = typer.Option(
    None,
    "--operators-from-masks",
    help="robomimic: label each demo by the mask key matching this glob (or any of "
    "several, comma-separated) that lists it, e.g. '*_operator_*' or 'base,conflict'.",
)
FILTER_KEY = typer.Option(
    None, "--filter-key", help="robomimic: import only the demos of mask/<KEY>."
)
TASK = typer.Option(None, "--task", help="Task name (default: from the dataset).")
CLIP = typer.Option(
    False, "--clip-actions", help="Clip actions outside their bounds instead of failing."
)
WARN = typer.Option(False, "--warn-actions", help="Keep out-of-bounds actions, with a warning.")
ACTION_BOUNDS = typer.Option(
    None,
    "--action-bounds",
    help="unit ([-1, 1]) or data (per-dim min/max). Default: unit for robomimic/npz, "
    "data for LeRobot.",
)
SKIP_BAD = typer.Option(
    False,
    "--skip-bad-episodes",
    help="Leave out episodes with NaN/inf values (listed) instead of failing.",
)
ALLOW_DUPLICATES = typer.Option(
    False,
    "--allow-duplicates",
    help="Keep episodes that repeat an earlier one step for step (refused otherwise).",
)


IMPORT_FLAGS = (
    ("fmt", str, FORMAT),
    ("obs_keys", str, OBS_KEYS),
    ("operator", str, OPERATOR),
    ("operators_from_masks", str, OPERATORS_FROM_MASKS),
    ("filter_key", str, FILTER_KEY),
    ("task", str, TASK),
    ("clip_actions", bool, CLIP),
    ("warn_actions", bool, WARN),
    ("action_bounds", str, ACTION_BOUNDS),
    ("skip_bad_episodes", bool, SKIP_BAD),
    ("allow_duplicates", bool, ALLOW_DUPLICATES),
)
"""The import flags as (parameter name, type, option), in the order ``--help`` lists them
(a command adds them with :func:`elicit_jax.cli.params.with_flags`)."""


def import_config(source: Path, out: Path | str, flags: Mapping[str, Any]) -> ImportConfig:
    """The ``ImportConfig`` of ``import``'s flags, checked the same way for every command
    that takes them (``import``, ``watch``).

    Args:
      source: the dataset to read.
      out: the demos artifact to write (``""``: none, ``watch`` keeps the demos in memory).
      flags: the command's parameters (``ctx.params``); those of :data:`IMPORT_FLAGS` are read.

    Returns:
      The import config.

    Raises:
      ElicitError: both ``--clip-actions`` and ``--warn-actions``, or unknown
        ``--action-bounds``.
    """
    from elicit_jax.data.convert import ImportConfig

    f = {name: flags[name] for name, _, _ in IMPORT_FLAGS}
    if f["clip_actions"] and f["warn_actions"]:
        raise ElicitError("choose one of --clip-actions and --warn-actions")
    if f["action_bounds"] not in (None, "unit", "data"):
        raise ElicitError(f"--action-bounds must be 'unit' or 'data', not {f['action_bounds']!r}")
    bounds = "clip" if f["clip_actions"] else "warn" if f["warn_actions"] else "error"
    return ImportConfig(
        source=str(source),
        out=str(out),
        format=f["fmt"],
        obs_keys=_split(f["obs_keys"]),
        operator=f["operator"],
        operators_from_masks=f["operators_from_masks"],
        filter_key=f["filter_key"],
        task=f["task"],
        bounds=bounds,
        action_bounds=f["action_bounds"],
        skip_bad_episodes=f["skip_bad_episodes"],
        allow_duplicates=f["allow_duplicates"],
    )


def _split(text: str | None) -> tuple[str, ...] | None:
    if not text:
        return None
    return tuple(k.strip() for k in text.split(",") if k.strip())


EXPORT_OUT = typer.Option(
    None,
    "-o",
    "--out",
    help="robomimic: the .hdf5 to write; lerobot: a new folder, or a .json episode list; "
    "npz: the .npz file.",
)
EPISODES = typer.Option(
    None, "--episodes", help="Only these episode ids of the selection, e.g. 0,3,5-8."
)
EXPORT_SOURCE = typer.Option(
    None, "--source", help="Original dataset (default: the one recorded at import)."
)
MASK_KEY = typer.Option(
    None,
    "--mask-key",
    help="robomimic: mark the selected demos of the source file with this filter key "
    "(without it: write the demos as a new file).",
)
IN_PLACE = typer.Option(
    False,
    "--in-place",
    help="robomimic: add the mask to the source file itself: a masked copy made beside it "
    "(room for one copy is needed), checked that nothing else changed, then renamed over it; "
    "on any failure the source is left as it was.",
)
EXPORT_OVERWRITE = typer.Option(
    False, "--overwrite", help="Replace an existing output, or an existing mask/<KEY>."
)
VERSION = typer.Option(
    None,
    "--version",
    help="LeRobot codebase version: v3.0 (the default, also for a selection of a v2.1 "
    "dataset: LeRobot 0.4 and later read only v3.0) or v2.1 (LeRobot 0.1-0.3).",
)
FRESH = typer.Option(
    False,
    "--fresh",
    help="lerobot: write the demos' own arrays as a new dataset even when they are whole "
    "episodes of a LeRobot dataset (whose cameras and other features are then not kept).",
)
FPS = typer.Option(
    None, "--fps", help="Frame rate of a new LeRobot dataset, when the demos do not tell it."
)
VALID_FRACTION = typer.Option(
    0.1, "--valid-fraction", help="New robomimic file: share of demos in mask/valid."
)
EXPORT_SEED = typer.Option(
    0, "--seed", help="Seed of the new robomimic file's train/valid split.", callback=check_seed
)


def export_config(selection: Path, flags: Mapping[str, Any]) -> ExportConfig:
    """The ``ExportConfig`` of ``export``'s flags (``flags``: the command's ``ctx.params``)."""
    from elicit_jax.data.export_config import ExportConfig
    from elicit_jax.data.selection import parse_episode_ids

    episodes, out, source = flags["episodes"], flags["out"], flags["source"]
    return ExportConfig(
        selection=str(selection),
        format=flags["fmt"],
        out=None if out is None else str(out),
        episodes=None if episodes is None else tuple(parse_episode_ids(episodes)),
        source=None if source is None else str(source),
        **{k: flags[k] for k in EXPORT_FLAGS},
    )


EXPORT_FLAGS = (
    "mask_key",
    "in_place",
    "overwrite",
    "version",
    "fresh",
    "fps",
    "valid_fraction",
    "seed",
)
"""The export flags passed to ``ExportConfig`` as they are."""
