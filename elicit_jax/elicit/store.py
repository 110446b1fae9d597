"""Durable session storage: one self-describing file per finished episode.

Layout of a session directory::

    SESSION/artifact.json          kind "elicit-session": config, inputs (hashes), train config
    SESSION/episodes/e000007.parquet   one per finished episode (kind "session-episode")
    SESSION/demos.parquet          accepted demonstrations (kind "demos", collect's schema)
    SESSION/policies/batch1/       π_new after each batch (training run directories)
    SESSION/manifest.json          a summary for people and tools (derived, never trusted)

An episode file is written atomically (temporary file, then rename) the moment the episode
ends, so a kill at any moment loses at most the episode in progress. Its rows are the
episode's control steps — ``step``, ``obs``, ``action`` (applied), ``operator`` (the operator
controlled the step; False for the robot's steps in HG-DAgger), ``qpos``/``qvel`` (the
simulator state the step started from: replaying the actions from the initial state, or
setting any row's state, reproduces the episode exactly), ``likelihood``, ``novelty``,
``compatibility``, ``incompatible`` (null on steps that were not scored: the robot's),
``time_s`` (since the episode started) and ``score_ms`` (the live scorer's latency). Its
header holds the episode's kind, seeds, verdict, the rule's verdict, the feedback shown and
its text, the policy it was scored against and timing.

Progress (phase, counts, which batch, which policy) is never stored separately: it is
recomputed from the episode files' headers, so it cannot disagree with them. The accepted
demonstrations are rebuilt from the episode files whenever they changed.
"""

from __future__ import annotations

import dataclasses
import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import (
    DIR_HEADER,
    check_artifact,
    clean_stale_temporaries,
    make_header,
    read_artifact,
    read_header,
    refuse_foreign_files,
    write_json,
    write_parquet,
)
from elicit_jax.elicit.events import FieldDifference, WindowFeedback, to_jsonable
from elicit_jax.errors import ElicitError
from elicit_jax.policy.checkpoint import run_owns

SESSION_KIND = "elicit-session"
EPISODE_KIND = "session-episode"
SCHEMA_VERSION = 1
EPISODES_DIR = "episodes"
POLICIES_DIR = "policies"
DEMOS_FILE = "demos.parquet"
MANIFEST_FILE = "manifest.json"
_SCORES = ("likelihood", "novelty", "compatibility")
_TEMP = re.compile(r"^\.(.+?)\.(?:p\d+-[0-9a-f]{8}\..*\.tmp|old-\d+)$")
"""A temporary of :func:`elicit_jax.artifact.atomic_path`; group 1 is the target's name."""


@dataclasses.dataclass(frozen=True)
class EpisodeRecord:
    """Everything recorded about one episode (T control steps).

    Attributes:
      index: session episode index.
      kind: ``practice`` or ``demonstration``.
      init_seed: simulator seed of the initial state.
      operator_seed: seed of the operator's randomness.
      batch: the batch a demonstration counts toward (1-based; 0 for practice).
      policy_batch: the policy that scored it (0 = the base policy, b = π_new after batch b).
      success: the task was completed.
      verdict: ``practice``, ``accepted``, ``rejected``, ``failed`` or ``unused`` (DAgger: no
        intervention).
      rule_verdict: what the accept/reject rule said: ``accept``, ``reject`` or ``""``.
      feedback: the flagged windows (computed on a rule rejection).
      feedback_shown: the verdict and feedback were shown to the operator (informed mode).
      text: one-line summary.
      obs: (T, O). action: (T, A). qpos: (T, nq). qvel: (T, nv).
      operator: (T,) bool, the operator controlled the step.
      likelihood, novelty, compatibility: (T,) float, NaN where not scored.
      incompatible: (T,) bool (False where not scored).
      time_s: (T,) seconds since the episode started. score_ms: (T,) scorer latency (NaN: none).
      meta: other header fields (timing, interventions, thresholds, ...).
    """

    index: int
    kind: str
    init_seed: int
    operator_seed: int
    batch: int
    policy_batch: int
    success: bool
    verdict: str
    rule_verdict: str
    feedback: tuple[WindowFeedback, ...]
    feedback_shown: bool
    text: str
    obs: np.ndarray
    action: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    operator: np.ndarray
    likelihood: np.ndarray
    novelty: np.ndarray
    compatibility: np.ndarray
    incompatible: np.ndarray
    time_s: np.ndarray
    score_ms: np.ndarray
    meta: dict[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def length(self) -> int:
        return len(self.obs)

    @property
    def scored(self) -> np.ndarray:
        """(T,) bool: steps with scores (the operator's)."""
        return np.isfinite(self.compatibility)

    @property
    def n_incompatible(self) -> int:
        return int(self.incompatible[self.scored].sum())

    @property
    def n_scored(self) -> int:
        return int(self.scored.sum())


def feedback_from_dict(d: dict[str, Any]) -> WindowFeedback:
    """Inverse of ``to_jsonable`` for a :class:`WindowFeedback`."""
    d = dict(d)
    d["fields"] = tuple(FieldDifference(**x) for x in d.get("fields", ()))
    d["actions"] = tuple(FieldDifference(**x) for x in d.get("actions", ()))
    d["plain"] = tuple(d.get("plain", ()))
    return WindowFeedback(**d)


def _fixed(arr: np.ndarray, dtype: Any) -> Any:
    import pyarrow as pa

    arr = np.ascontiguousarray(arr, dtype=dtype)
    width = arr.shape[1] if arr.ndim == 2 else 0
    return pa.FixedSizeListArray.from_arrays(pa.array(arr.reshape(-1)), width)


def _nullable(arr: np.ndarray, mask: np.ndarray, dtype: Any) -> Any:
    import pyarrow as pa

    return pa.array(np.asarray(arr, dtype), mask=~mask)


def record_table(rec: EpisodeRecord) -> Any:
    """The per-step rows of an episode as a ``pyarrow.Table``."""
    import pyarrow as pa

    scored = rec.scored
    cols = {
        "step": pa.array(np.arange(rec.length, dtype=np.int32)),
        "obs": _fixed(rec.obs, np.float32),
        "action": _fixed(rec.action, np.float32),
        "operator": pa.array(np.asarray(rec.operator, bool)),
        "qpos": _fixed(rec.qpos, np.float64),
        "qvel": _fixed(rec.qvel, np.float64),
        **{k: _nullable(np.nan_to_num(getattr(rec, k)), scored, np.float32) for k in _SCORES},
        "incompatible": _nullable(rec.incompatible, scored, bool),
        "time_s": pa.array(np.asarray(rec.time_s, np.float64)),
        "score_ms": _nullable(np.nan_to_num(rec.score_ms), np.isfinite(rec.score_ms), np.float32),
    }
    return pa.table(cols)


_SESSION_FILE = re.compile(
    r"^(artifact\.json|manifest\.json|demos\.parquet|episodes/e\d+\.parquet"
    r"|report/(artifact\.json|report\.md|report\.html|session\.png))$"
)
"""The files of a session (see the module docstring), its report's included; each batch
policy under ``policies/batch<b>/`` is a training run (:func:`run_owns`)."""


def session_owns(relative: str) -> bool:
    """Whether a session writes the file at ``relative`` (a POSIX path in its folder)."""
    batch = re.match(r"^policies/batch\d+/(.+)$", relative)
    return bool(_SESSION_FILE.match(relative)) or bool(batch and run_owns(batch.group(1)))


class SessionStore:
    """The files of one session directory (see the module docstring)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    @property
    def episodes_dir(self) -> Path:
        return self.root / EPISODES_DIR

    @property
    def demos_path(self) -> Path:
        return self.root / DEMOS_FILE

    def header(self) -> dict[str, Any]:
        """The session header (``artifact.json``)."""
        return read_artifact(self.root, SESSION_KIND, SCHEMA_VERSION, what="a session")

    def create(self, header: dict[str, Any]) -> None:
        """Start an empty session directory with ``header``."""
        self.episodes_dir.mkdir(parents=True, exist_ok=True)
        write_json(self.root / DIR_HEADER, header)

    def wipe(self) -> None:
        """Remove a session directory (``--overwrite``): only ever a session, and only when
        it holds nothing but a session's files (:func:`session_owns`); the user's own files
        in it are named instead."""
        self.header()
        refuse_foreign_files(self.root, session_owns, "an elicitation session")
        shutil.rmtree(self.root)

    def clean_temporaries(self) -> list[Path]:
        """Remove temporaries of writes a killed session left (only those of processes that
        no longer exist: :func:`elicit_jax.artifact.clean_stale_temporaries`)."""
        removed: list[Path] = []
        for d in (self.root, self.episodes_dir, self.root / POLICIES_DIR):
            if d.is_dir():
                targets = {m.group(1) for p in d.iterdir() if (m := _TEMP.match(p.name))}
                for name in sorted(targets):
                    removed += clean_stale_temporaries(d / name)
        return removed

    def episode_path(self, index: int) -> Path:
        return self.episodes_dir / f"e{index:06d}.parquet"

    def policy_dir(self, batch: int) -> Path:
        return self.root / POLICIES_DIR / f"batch{batch}"

    def write_episode(self, rec: EpisodeRecord, extra_header: dict[str, Any]) -> Path:
        """Atomically write one finished episode."""
        path = self.episode_path(rec.index)
        if path.exists():
            raise ElicitError("episode file already exists (a second writer?)", path)
        fields = {
            "index": rec.index,
            "episode_kind": rec.kind,
            "init_seed": rec.init_seed,
            "operator_seed": rec.operator_seed,
            "batch": rec.batch,
            "policy_batch": rec.policy_batch,
            "success": rec.success,
            "verdict": rec.verdict,
            "rule_verdict": rec.rule_verdict,
            "feedback": to_jsonable(list(rec.feedback)),
            "feedback_shown": rec.feedback_shown,
            "text": rec.text,
            "length": rec.length,
            "n_scored": rec.n_scored,
            "n_incompatible": rec.n_incompatible,
            "operator_steps": int(np.asarray(rec.operator, bool).sum()),
            "obs_dim": int(rec.obs.shape[1]),
            "action_dim": int(rec.action.shape[1]),
            **to_jsonable(rec.meta),
        }
        header = make_header(EPISODE_KIND, SCHEMA_VERSION, **extra_header, **fields)
        write_parquet(path, record_table(rec), header)
        return path

    def episode_files(self) -> list[Path]:
        """Finished episode files, in index order."""
        if not self.episodes_dir.is_dir():
            return []
        return sorted(self.episodes_dir.glob("e*.parquet"))

    def episode_headers(self) -> list[dict[str, Any]]:
        """Headers of the finished episodes, in index order; an unreadable file is an error."""
        out = []
        for p in self.episode_files():
            try:
                h = read_header(p)
            except ElicitError as e:
                raise ElicitError(
                    f"episode file is unreadable ({e}); it was not written by a finished "
                    "episode: move it out of the session to record that episode again",
                    p,
                ) from e
            check_artifact(h, p, EPISODE_KIND, SCHEMA_VERSION, what="an episode of a session")
            if f"e{int(h.get('index', -1)):06d}" != p.stem:
                raise ElicitError("is not an episode of this session", p)
            out.append(h)
        return out

    def read_episode(self, index: int) -> EpisodeRecord:
        """Read one finished episode back."""
        from elicit_jax.data.columns import fixed_to_numpy, read_table

        path = self.episode_path(index)
        h = read_artifact(path, EPISODE_KIND, SCHEMA_VERSION, what="an episode of a session")
        t = read_table(path)

        def scores(name: str) -> np.ndarray:
            col = t.column(name).combine_chunks()
            return np.asarray(col.to_numpy(zero_copy_only=False), np.float64)

        inc = t.column("incompatible").combine_chunks()
        known = {f.name for f in dataclasses.fields(EpisodeRecord)}
        meta_keys = set(h) - known - {"episode_kind", "length", "n_scored", "n_incompatible"}
        return EpisodeRecord(
            index=int(h["index"]),
            kind=str(h["episode_kind"]),
            init_seed=int(h["init_seed"]),
            operator_seed=int(h["operator_seed"]),
            batch=int(h["batch"]),
            policy_batch=int(h["policy_batch"]),
            success=bool(h["success"]),
            verdict=str(h["verdict"]),
            rule_verdict=str(h["rule_verdict"]),
            feedback=tuple(feedback_from_dict(d) for d in h.get("feedback", [])),
            feedback_shown=bool(h["feedback_shown"]),
            text=str(h.get("text", "")),
            obs=fixed_to_numpy(t, "obs", path),
            action=fixed_to_numpy(t, "action", path),
            qpos=fixed_to_numpy(t, "qpos", path, np.float64),
            qvel=fixed_to_numpy(t, "qvel", path, np.float64),
            operator=t.column("operator").to_numpy(),
            likelihood=scores("likelihood"),
            novelty=scores("novelty"),
            compatibility=scores("compatibility"),
            incompatible=np.asarray(inc.fill_null(False).to_numpy(zero_copy_only=False), bool),
            time_s=t.column("time_s").to_numpy(),
            score_ms=scores("score_ms"),
            meta={k: h[k] for k in sorted(meta_keys)},
        )

    def write_manifest(self, summary: dict[str, Any]) -> None:
        """The human-readable summary (derived from the episode files)."""
        write_json(self.root / MANIFEST_FILE, summary)
