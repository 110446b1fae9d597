"""What ``elicit-jax export`` is asked to do (:class:`ExportConfig`, checked when built) and
which existing output it may replace (:func:`is_lerobot_dataset`); the export itself is
:func:`elicit_jax.data.export.export_dataset`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Literal

from elicit_jax.artifact import read_header
from elicit_jax.errors import ElicitError

Format = Literal["robomimic", "lerobot", "npz"]
FORMATS = ("robomimic", "lerobot", "npz")
EXPORT_KIND = "export"
EXPORT_SCHEMA_VERSION = 2


@dataclasses.dataclass(frozen=True)
class ExportConfig:
    """How to export a selection of episodes (what is written: :mod:`elicit_jax.data.export`).

    Attributes:
      selection: a demos ``.parquet`` (its episodes are the selection) or an episode-list
        ``.json``.
      format: ``robomimic``, ``lerobot`` or ``npz``.
      out: destination file or folder (``None`` with ``in_place``).
      episodes: narrow the selection to these episode ids.
      source: the original dataset; default the source recorded at import.
      mask_key: robomimic: mark the selected demos of the source file with this filter key.
      in_place: robomimic: write the mask into the source file itself.
      overwrite: replace an existing output, or an existing ``mask/<mask_key>``.
      version: LeRobot codebase version, ``v3.0`` (the default: LeRobot 0.4 and later read
        nothing else) or ``v2.1`` (LeRobot 0.1-0.3), also for a selection of a v2.x dataset.
      fresh: lerobot: write the demos' own arrays even for whole episodes of a LeRobot source.
      fps: frame rate of a new LeRobot dataset when the demos do not tell it.
      valid_fraction: new robomimic file: share of demos in ``mask/valid``.
      seed: seed of that train/valid split.
    """

    selection: str
    format: Format
    out: str | None = None
    episodes: tuple[int, ...] | None = None
    source: str | None = None
    mask_key: str | None = None
    in_place: bool = False
    overwrite: bool = False
    version: str | None = None
    fresh: bool = False
    fps: float | None = None
    valid_fraction: float = 0.1
    seed: int = 0

    def __post_init__(self) -> None:
        if self.format not in FORMATS:
            raise ElicitError(f"unknown format {self.format!r}; choose one of {', '.join(FORMATS)}")
        if self.in_place and (self.format != "robomimic" or not self.mask_key):
            raise ElicitError(
                "--in-place adds a robomimic mask: it needs --format robomimic and --mask-key"
            )
        if self.in_place and self.out is not None:
            raise ElicitError("give -o/--out or --in-place, not both")
        if not self.in_place and self.out is None:
            raise ElicitError("export needs -o/--out (or --in-place for a robomimic mask)")
        if self.version not in (None, "v2.1", "v3.0"):
            raise ElicitError(f"--version must be v2.1 or v3.0, not {self.version!r}")
        if self.fps is not None and not self.fps > 0:
            raise ElicitError(f"--fps must be positive, not {self.fps}")
        if not 0 <= self.valid_fraction < 1:
            raise ElicitError(f"--valid-fraction must lie in [0, 1), not {self.valid_fraction}")
        if self.mask_key and self.format != "robomimic":
            raise ElicitError("--mask-key applies to --format robomimic only")


def is_lerobot_dataset(path: Path) -> bool:
    """``path`` is a LeRobot dataset folder that elicit-jax exported (``meta/info.json`` and
    an ``artifact.json`` of kind ``export``): an earlier export that ``--overwrite`` may
    replace, unlike any other directory — a dataset LeRobot recorded or downloaded is never
    replaced."""
    path = Path(path)
    if not (path / "meta" / "info.json").is_file():
        return False
    try:
        return read_header(path).get("kind") == EXPORT_KIND
    except ElicitError:
        return False
