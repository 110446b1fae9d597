"""The base policy's own training demonstrations, as the trust checks of thresholds need them.

Thresholds that reject the demonstrations the base policy learned from are wrong, whatever
the contrast sets say, and a contrast set that holds training demonstrations is scored
in-sample (:mod:`elicit_jax.compat.trust`). Both checks need to know, for the policy a scores
file was computed with, which demonstrations it was trained on. Demonstrations are matched by
content — the hash of an episode's observations and actions
(:func:`~elicit_jax.data.duplicates.episode_digests`) — never by id, since ids change between a
file and its subsets.

Where the evidence comes from, in this order:
  * the policy: the checkpoint the scores file records (``inputs.policy``, checked by hash);
  * the training demos' hashes: the checkpoint's ``episode_sha256`` (recorded by ``train``),
    else computed from the training data below;
  * their ℓ and ν: the rows of the scores file whose episode is a training demo (the README
    walk scores every demo, training ones included); the training demos not in it are scored
    under the same policy and settings, read from ``--base`` or from the training data file
    the checkpoint records (checked by hash: a file that is not the training data is refused).

What cannot be established is said, with why, as a note; nothing is guessed.

Example:
    >>> ev = gather("scores.parquet", header, columns)
    >>> ev.n_demos, ev.notes
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import read_header
from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.data.demo_set import Demos
from elicit_jax.data.duplicates import episode_digests
from elicit_jax.errors import ElicitError
from elicit_jax.hashing import matches_recorded


@dataclasses.dataclass(frozen=True)
class TrainingEvidence:
    """What is known about the base policy's training demonstrations.

    Attributes:
      training: content hashes of the training demos (None: unknown).
      scored: episode id in the scores -> content hash (None: the scored file is unknown).
      ell: (P,) likelihood errors of the training demos' pairs under the scoring policy.
      nu: (P,) novelties of those pairs.
      episode: (P,) index of each pair's training demo.
      source: where ``ell``/``nu`` came from, for messages.
      notes: what could not be established, each with its reason.
    """

    training: frozenset[str] | None = None
    scored: Mapping[int, str] | None = None
    ell: np.ndarray | None = None
    nu: np.ndarray | None = None
    episode: np.ndarray | None = None
    source: str = ""
    notes: tuple[str, ...] = ()

    @property
    def n_demos(self) -> int:
        """Training demos whose scores are known."""
        return 0 if self.episode is None else len(np.unique(self.episode))

    def rejected(self, thresholds: Thresholds, accept_fraction: float) -> int:
        """Training demos the 5% rule rejects under (λ, η)."""
        from elicit_jax.compat.measures import is_incompatible

        if self.episode is None:
            return 0
        _, index = np.unique(self.episode, return_inverse=True)
        n_inc = np.bincount(index, weights=is_incompatible(self.ell, self.nu, *thresholds.pair))
        return int((n_inc > accept_fraction * np.bincount(index)).sum())


def _recorded(rec: Mapping[str, Any], *near: Path) -> tuple[Path | None, str]:
    """The file an artifact records as an input, if still there and unchanged: at its
    recorded path, else (relative paths) under each of ``near``, else under its name there
    (an output directory renamed into place after writing)."""
    p = Path(rec["path"])
    tries = [p] + [n / p for n in near if not p.is_absolute()] + [n / p.name for n in near]
    found = [t for t in dict.fromkeys(tries) if t.exists()]
    if not found:
        return None, f"{rec['path']} is not there"
    for t in found:
        if not rec.get("sha256") or matches_recorded(rec["sha256"], t):
            return t, ""
    return None, f"{found[0]} changed since it was recorded"


def _checkpoint(header: Mapping[str, Any], near: Path) -> tuple[Path | None, dict, str]:
    """The seed directory of the policy a scores file was computed with, and its header."""
    from elicit_jax.policy.checkpoint import seed_dirs

    rec = (header.get("inputs") or {}).get("policy")
    if not rec:
        return None, {}, "the scores file records no policy checkpoint"
    path, why = _recorded(rec, near)
    if path is None:
        return None, {}, f"the policy the scores were computed with: {why}"
    try:
        dirs = seed_dirs(path)
    except ElicitError as e:
        return None, {}, f"the policy the scores were computed with: {e}"
    seed = (header.get("policy") or {}).get("seed")
    seed_dir = dirs.get(int(seed)) if seed is not None else next(iter(dirs.values()))
    if seed_dir is None:
        return None, {}, f"the policy {path} has no seed {seed}"
    return seed_dir, read_header(seed_dir), ""


def _matches(demos: Demos, ckpt: Mapping[str, Any]) -> bool:
    """Whether ``demos`` are the data the checkpoint was trained on (ids aside)."""
    from elicit_jax.data.demos import concat_demos
    from elicit_jax.policy.dataset import demos_sha256

    if "episode_sha256" in ckpt:
        return sorted(episode_digests(demos).values()) == sorted(ckpt["episode_sha256"].values())
    want = ckpt.get("data_sha256")
    return want in (demos_sha256(demos), demos_sha256(concat_demos([demos])))


def _read_all(paths: Sequence[str | Path]) -> Demos:
    """One file as it is, several concatenated (as ``train`` and the pipelines read them)."""
    from elicit_jax.data.demos import concat_demos, read_demos

    return concat_demos([read_demos(p) for p in paths]) if len(paths) > 1 else read_demos(paths[0])


def _training_demos(
    ckpt: Mapping[str, Any], seed_dir: Path, base: Sequence[str | Path], near: Path
) -> tuple[Demos | None, str]:
    """The training demonstrations: ``base`` (checked against the checkpoint) or the files
    the checkpoint records."""
    if base:
        demos = _read_all(base)
        if not _matches(demos, ckpt):
            raise ElicitError(
                f"is not the data the base policy {seed_dir} was trained on (content hashes "
                "differ): give the file it was trained on with --base",
                base[0],
            )
        return demos, ""
    recorded = {k: v for k, v in (ckpt.get("inputs") or {}).items() if k.startswith("demos")}
    if not recorded:
        return None, f"{seed_dir} records no training data file"
    paths = []
    for name in sorted(recorded):
        path, why = _recorded(recorded[name], near, seed_dir)
        if path is None:
            return None, f"the training data {why}"
        paths.append(path)
    demos = _read_all(paths)
    return (demos, "") if _matches(demos, ckpt) else (None, "its training data file differs")


def _scored_digests(header: Mapping[str, Any], near: Path) -> tuple[dict[int, str] | None, str]:
    from elicit_jax.data.demos import read_demos

    rec = (header.get("inputs") or {}).get("demos")
    if not rec:
        return None, "the scores file records no demonstrations file"
    path, why = _recorded(rec, near)
    if path is None:
        return None, f"the scored demonstrations: {why}"
    return episode_digests(read_demos(path)), ""


def _score_missing(
    demos: Demos, missing: set[str], seed_dir: Path, header: Mapping[str, Any]
) -> dict[str, np.ndarray]:
    """ℓ, ν of the training demos whose hash is in ``missing``, under the scoring policy."""
    from elicit_jax.compat.measures import config_from_dict
    from elicit_jax.compat.score import score_demos
    from elicit_jax.policy.loaded import load_policy

    digests = episode_digests(demos)
    chosen = demos.select_episodes([e for e, d in digests.items() if d in missing])
    which = (header.get("policy") or {}).get("which", "best")
    policy = load_policy(seed_dir, which).policy
    config = config_from_dict(dict(header.get("config") or {}), "the scores file's config")
    return score_demos(policy, chosen, config)


def gather(
    scores_path: str | Path,
    header: Mapping[str, Any],
    columns: Mapping[str, np.ndarray],
    base: Sequence[str | Path] = (),
) -> TrainingEvidence:
    """Collect the :class:`TrainingEvidence` for a scores file.

    Args:
      scores_path: the scores artifact (relative recorded paths are also tried next to it).
      header: its header.
      columns: its ``episode``, ``likelihood`` and ``novelty`` columns.
      base: the base policy's training demonstrations (``--base``); default: the files the
        checkpoint records.

    Raises:
      ElicitError: ``base`` is not the data the policy was trained on.
    """
    near = Path(scores_path).parent
    seed_dir, ckpt, why = _checkpoint(header, near)
    scored, scored_why = _scored_digests(header, near)
    notes = []
    if scored is None:
        notes.append(f"whether the contrast sets overlap the training data ({scored_why})")
    if seed_dir is None:
        if base:
            raise ElicitError(f"cannot check --base against the policy: {why}", base[0])
        return TrainingEvidence(scored=scored, notes=(f"the training-data checks ({why})",))
    demos, demos_why = _training_demos(ckpt, seed_dir, base, near)
    training = ckpt.get("episode_sha256")
    if training is None and demos is not None:
        training = episode_digests(demos)
    if training is None:
        what = "the training-data checks"
        return TrainingEvidence(scored=scored, notes=(f"{what} ({demos_why}; pass --base)",))
    hashes = frozenset(training.values())
    ep = np.asarray(columns["episode"])
    found = {e: d for e, d in (scored or {}).items() if d in hashes}
    first = {d: e for e, d in sorted(found.items(), reverse=True)}  # one copy per demo
    keep = np.isin(ep, list(first.values()))
    ell, nu, idx = [columns["likelihood"][keep]], [columns["novelty"][keep]], [ep[keep]]
    missing = set(hashes) - set(first)
    source = f"{len(first)} scored in this file" if first else ""
    if missing and demos is not None:
        s = _score_missing(demos, missing, seed_dir, header)
        ell.append(s["likelihood"])
        nu.append(s["novelty"])
        idx.append(np.asarray(s["episode"]) + int(ep.max(initial=0)) + 1)
        source = ", ".join(filter(None, [source, f"{len(missing)} scored now under {seed_dir}"]))
        missing = set()
    if missing:
        notes.append(
            f"{len(missing)} of the {len(hashes)} training demonstrations ({demos_why}; pass "
            "--base with the file the policy was trained on)"
        )
    return TrainingEvidence(
        training=hashes,
        scored=scored,
        ell=np.concatenate(ell),
        nu=np.concatenate(nu),
        episode=np.concatenate(idx),
        source=source,
        notes=tuple(notes),
    )
