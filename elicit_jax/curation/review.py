"""A person's review of a demos file: per-episode facts (M, quality flags, operator), the
reviewer's flags with reasons, and the export of what is kept (``elicit-jax review``; the page
is :mod:`elicit_jax.web.review`).

The reviewer's flags live in ``OUT/review.json`` (written atomically after every change, so a
restarted review resumes). :meth:`Review.export` writes the kept episodes (every episode not
flagged) as a ``demos`` artifact, ``OUT/kept.parquet``, and hands them back to the source
dataset through the existing exporter (:func:`elicit_jax.data.export.export_dataset`): a copy
of the robomimic file with ``mask/<key>`` listing them, or a LeRobot episode list.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError

STATE_FILE = "review.json"
KEPT_FILE = "kept.parquet"
MAX_REASON = 200
MASK_KEY_RE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,59}")


@dataclasses.dataclass(frozen=True)
class ReviewConfig:
    """What to review and where the review goes.

    Attributes:
      demos: the demos artifact.
      out: folder of the review's state and exports.
      scores: compatibility scores of ``demos`` (per-step M), optional.
      quality: ``elicit-jax quality`` output of ``demos``, optional.
    """

    demos: str
    out: str
    scores: str | None = None
    quality: str | None = None


def _scores_by_episode(path: str, demos: Any, demos_path: str) -> dict[int, np.ndarray]:
    from elicit_jax.artifact import matches_recorded
    from elicit_jax.compat.score_file import read_scores

    header, cols = read_scores(path, ["episode", "step", "compatibility"])
    recorded = ((header.get("inputs") or {}).get("demos") or {}).get("sha256")
    if recorded and not matches_recorded(recorded, demos_path):
        raise ElicitError(f"these scores were computed on another demos file, not {demos_path}",
                          path)  # fmt: skip
    out: dict[int, np.ndarray] = {}
    for e, s, t in demos.episode_bounds():
        rows = np.flatnonzero(cols["episode"] == e)
        if len(rows) != t - s:
            raise ElicitError(f"scores have {len(rows)} steps of episode {e}, not {t - s}", path)
        out[int(e)] = np.asarray(cols["compatibility"], float)[rows][np.argsort(cols["step"][rows])]
    return out


def _quality_by_episode(path: str, ids: list[int]) -> dict[int, tuple[bool, str]]:
    from elicit_jax.curation.quality import read_quality

    table = read_quality(path)
    got = {int(e): (bool(f), str(r)) for e, f, r in zip(*(table[c] for c in
           ("episode", "flagged", "reason")), strict=True)}  # fmt: skip
    if sorted(got) != sorted(ids):
        raise ElicitError("these quality flags are of another demos file", path)
    return got


def _saved_flags(flags: Any, episodes: set[int], state: Path) -> dict[int, str]:
    """The reviewer's flags as saved in ``review.json``: episode id -> a one-line reason.

    Raises:
      ElicitError: naming ``state``: not an object of episode ids of the demos to reasons.
    """
    if not isinstance(flags, dict):
        raise ElicitError("malformed review state: 'flags' is not an object", state)
    out: dict[int, str] = {}
    for key, reason in flags.items():
        if not (isinstance(key, str) and key.isdigit() and int(key) in episodes):
            raise ElicitError(
                f"malformed review state: flag {key!r} names no episode of the demos", state
            )
        if not isinstance(reason, str) or not reason.strip() or len(reason) > MAX_REASON:
            raise ElicitError(
                f"malformed review state: the reason for episode {key} is not a one-line text "
                f"of 1..{MAX_REASON} characters",
                state,
            )
        out[int(key)] = " ".join(reason.split())
    return out


def check_review_folder(path: str | Path) -> None:
    """Error unless ``path`` can hold a review: new, empty, or an earlier review's folder
    (it holds ``review.json``). A file or another folder is never written into."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ElicitError("is a file; the review folder (-o) is a directory", path)
    if path.is_dir() and any(path.iterdir()) and not (path / STATE_FILE).exists():
        raise ElicitError(
            f"is a folder but not a review's (no {STATE_FILE}); give a new folder or an "
            "earlier review's",
            path,
        )


class Review:
    """The state of one review (the only mutable part: the reviewer's flags).

    Args:
      config: what to review.
    """

    def __init__(self, config: ReviewConfig) -> None:
        from elicit_jax.artifact import read_json
        from elicit_jax.data.demos import read_demos

        self.config = config
        self.demos = read_demos(config.demos)
        self.bounds = {int(e): (int(s), int(t)) for e, s, t in self.demos.episode_bounds()}
        ids = list(self.bounds)
        check_review_folder(config.out)
        self.m = (
            {}
            if config.scores is None
            else _scores_by_episode(config.scores, self.demos, config.demos)
        )
        self.quality = {} if config.quality is None else _quality_by_episode(config.quality, ids)
        self.out = Path(config.out)
        self.flags: dict[int, str] = {}
        state = self.out / STATE_FILE
        if state.exists():
            saved = read_json(state)
            if not isinstance(saved, dict):
                raise ElicitError("malformed review state: not a JSON object", state)
            if saved.get("demos_sha256") != self._demos_hash():
                raise ElicitError("this review folder is of another demos file", state)
            self.flags = _saved_flags(saved.get("flags", {}), set(self.bounds), state)

    def _demos_hash(self) -> str:
        from elicit_jax.artifact import file_sha256

        return file_sha256(self.config.demos)

    def episodes(self) -> list[dict[str, Any]]:
        """One row per episode: id, operator, steps, success, source name, mean M and
        incompatible steps (with scores), quality flag and reason, the reviewer's flag."""
        from elicit_jax.data.demo_set import SOURCE_EPISODE

        names = self.demos.extra.get(SOURCE_EPISODE)
        rows = []
        for e, (s, t) in self.bounds.items():
            m = self.m.get(e)
            q = self.quality.get(e)
            rows.append(
                {
                    "episode": e,
                    "operator": str(self.demos.operator[s]),
                    "steps": t - s,
                    "success": bool(self.demos.success[s]),
                    "source_episode": None if names is None else str(names[s]),
                    "m_mean": None if m is None else float(m.mean()),
                    "incompatible": None if m is None else int((m == 0).sum()),
                    "quality_flagged": None if q is None else q[0],
                    "quality_reason": None if q is None else q[1],
                    "flagged": e in self.flags,
                    "reason": self.flags.get(e, ""),
                }
            )
        return rows

    def episode(self, e: int) -> dict[str, Any]:
        """An episode's observations ``(T, O)``, actions and per-step M (or None)."""
        if e not in self.bounds:
            raise ElicitError(f"no episode {e}")
        s, t = self.bounds[e]
        m = self.m.get(e)
        return {"obs": self.demos.obs[s:t], "action": self.demos.action[s:t], "m": m}

    def flag(self, e: int, flagged: bool, reason: str = "") -> None:
        """Flag (drop) or unflag episode ``e``; a flag needs a one-line reason."""
        if e not in self.bounds:
            raise ElicitError(f"no episode {e}")
        reason = " ".join(str(reason).split())
        if flagged and not reason:
            raise ElicitError("say why the episode is flagged (a one-line reason)")
        if len(reason) > MAX_REASON:
            raise ElicitError(f"a reason has at most {MAX_REASON} characters")
        if flagged:
            self.flags[e] = reason
        else:
            self.flags.pop(e, None)
        self._save()

    def _save(self) -> None:
        from elicit_jax.artifact import write_json

        self.out.mkdir(parents=True, exist_ok=True)
        write_json(
            self.out / STATE_FILE,
            {
                "kind": "review",
                "demos": str(self.config.demos),
                "demos_sha256": self._demos_hash(),
                "flags": {str(k): v for k, v in sorted(self.flags.items())},
            },
        )

    def export(self, fmt: str | None = None, mask_key: str = "reviewed") -> dict[str, Any]:
        """Write the kept episodes as ``OUT/kept.parquet``; with ``fmt`` ``robomimic`` also a
        copy of the source file with ``mask/<mask_key>`` (``OUT/reviewed.hdf5``), with
        ``lerobot`` an episode list (``OUT/episodes.json``).

        A mask key the source file already has (its own ``base``, an operator's mask, an
        earlier export's) is refused: the review adds a list of demos, it never replaces one.
        Errors say what the review page offers instead (its errors are shown there).

        Returns:
          ``{"kept", "dropped", "demos", "export"}`` (paths as strings).
        """
        from elicit_jax.data.export import export_dataset
        from elicit_jax.data.export_config import ExportConfig
        from elicit_jax.data.subsets import SubsetSpec, select_file

        if fmt not in (None, "robomimic", "lerobot"):
            raise ElicitError(f"export format must be robomimic or lerobot, not {fmt!r}")
        keep = [e for e in self.bounds if e not in self.flags]
        if not keep:
            raise ElicitError("every episode is flagged: nothing to keep")
        instead = (
            f"choose 'demos artifact only': {KEPT_FILE} holds the kept episodes"
            if fmt == "robomimic"
            else f"choose 'demos artifact only' or '+ robomimic mask': {KEPT_FILE} holds the "
            "kept episodes"
        )
        if fmt == "robomimic":
            self._check_mask_key(mask_key, instead)
        self._save()  # the folder is a review's from its first file on (see check_review_folder)
        kept = self.out / KEPT_FILE
        spec = SubsetSpec(episodes=",".join(str(e) for e in keep))
        select_file(self.config.demos, kept, spec)
        result = {"kept": len(keep), "dropped": len(self.flags), "demos": str(kept), "export": None}
        if fmt is not None:
            dest = self.out / ("reviewed.hdf5" if fmt == "robomimic" else "episodes.json")
            cfg = ExportConfig(
                selection=str(kept),
                format=fmt,  # type: ignore[arg-type]
                out=str(dest),
                mask_key=mask_key if fmt == "robomimic" else None,
                overwrite=True,  # the review's own earlier export (mask keys are checked above)
            )
            export_dataset(cfg, instead=instead)
            result["export"] = str(dest)
        return result

    def _check_mask_key(self, key: str, instead: str) -> None:
        """Error unless ``key`` is a new mask of the demos' source robomimic file."""
        from elicit_jax.data.export import mask_source
        from elicit_jax.data.robomimic import open_hdf5

        if not MASK_KEY_RE.fullmatch(key):
            raise ElicitError(
                "a mask key is 1-60 letters, digits, '_', '-' or '.' (a letter or digit first), "
                f"not {key[:60]!r}"
            )
        source = mask_source(str(self.config.demos), instead)
        with open_hdf5(source) as f:
            taken = sorted(f["mask"].keys()) if "mask" in f else []
        if key in taken:
            raise ElicitError(
                f"the source file already has a mask '{key}' (its masks: {', '.join(taken)}); "
                "type a new mask key: the review never replaces an existing mask",
                source,
            )
