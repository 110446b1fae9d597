"""Gather an elicitation study's run directory into :class:`StudyData` for its report.

Reads the run manifest and, per finished stage: evaluations (success per training seed, best
checkpoint — the filtering report's :func:`~elicit_jax.pipeline.evidence.result_rows_of`),
sessions (per-episode summaries from the episode files, and the person's record of what it
changed), M-filter counts, thresholds and D_base's lengths. Unfinished stages are listed in a
note, so a partial run's report is right about what it shows.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import read_header, read_json
from elicit_jax.compat.thresholds import read_thresholds, read_thresholds_header
from elicit_jax.pipeline.gather import gather_fields
from elicit_jax.pipeline.gather_rows import kept_counts
from elicit_jax.pipeline.report_rows import RunReport
from elicit_jax.pipeline.stage_kind import StageKinds

STUDY_REPORT_STAGE = "study-report"
"""The stage kind of an elicitation study's report stage."""
PERSON_FILE = "person.json"
"""Beside a study's session: the person's traits, starting and final choices, every change."""
DISTANCE_KEY = "distance_from_base"
"""In a person record: ``{"start": d, "end": d}``, its starting and final θ's distance from
the base operator's (sessions recorded before this key have none)."""


@dataclasses.dataclass(frozen=True)
class SessionData:
    """One finished session of one simulated person.

    Attributes:
      task, model, condition: where it belongs (condition: naive, informed, an ablation arm,
        naive-dagger, informed-dagger).
      person: the person's id in the study (``p0``, ...).
      spec: the person's operator spec.
      dagger: an HG-DAgger session.
      rows: per-episode summaries (kind, verdict, rule verdict, length, operator steps,
        incompatible fraction, intervention rate, ...), in episode order.
      person_record: what the person recorded (traits, starting and final choices, changes).
      end_reason: ``complete`` or ``max-episodes`` (empty while running).
    """

    task: str
    model: str
    condition: str
    person: str
    spec: str
    dagger: bool
    rows: tuple[Mapping[str, Any], ...]
    person_record: Mapping[str, Any]

    @property
    def style(self) -> str:
        return self.spec.partition(":")[2].split(",")[0]

    @property
    def demonstrations(self) -> list[Mapping[str, Any]]:
        return [r for r in self.rows if r["episode_kind"] == "demonstration"]

    @property
    def accepted(self) -> list[Mapping[str, Any]]:
        return [r for r in self.rows if r["verdict"] == "accepted"]


@dataclasses.dataclass(frozen=True)
class FilterCount:
    """What the M-filter kept of one naive session."""

    task: str
    model: str
    person: str
    pairs_kept: int
    pairs_total: int
    episodes_kept: int
    episodes_total: int


@dataclasses.dataclass(frozen=True)
class StudyData(RunReport):
    """Everything the study report shows: what every report shows (:class:`RunReport`) and
    the sessions, D_base's lengths and first states, the thresholds and the M-filter counts."""

    sessions: tuple[SessionData, ...]
    base_lengths: Mapping[str, tuple[float, float, int]]
    base_states: Mapping[str, tuple[Any, ...]]
    thresholds: Mapping[tuple[str, str], Mapping[str, Any]]
    filters: tuple[FilterCount, ...]
    configs: Mapping[str, Any]
    versions: Mapping[str, str]


def _lengths(path: Path) -> tuple[float, float, int]:
    import pyarrow.parquet as pq

    episode = pq.read_table(path, columns=["episode"]).column("episode").to_numpy()
    _, counts = np.unique(episode, return_counts=True)
    return (
        float(counts.mean()),
        float(counts.std(ddof=1)) if counts.size > 1 else 0.0,
        int(counts.size),
    )


def _first_states(path: Path, n: int = 3) -> tuple[Any, ...]:
    """States ``(T, O)`` of D_base's first ``n`` demonstrations (to compare styles on)."""
    from elicit_jax.data.demos import read_demos

    demos = read_demos(path)
    return tuple(np.asarray(demos.obs[s:t]) for _, s, t in list(demos.episode_bounds())[:n])


def session_data(stage: Mapping[str, Any], path: Path) -> SessionData | None:
    """A finished session stage's data (None when its person record is not written yet)."""
    from elicit_jax.elicit.progress import summary_row
    from elicit_jax.elicit.store import SessionStore

    if not (path / PERSON_FILE).exists():
        return None
    cfg = stage["config"]
    rows = tuple(summary_row(h) for h in SessionStore(path).episode_headers())
    return SessionData(
        task=cfg["task"],
        model=cfg["model"],
        condition=cfg["condition"],
        person=cfg["person"],
        spec=cfg["session"]["operator"],
        dagger=bool(cfg["session"]["dagger"]),
        rows=rows,
        person_record=read_json(path / PERSON_FILE),
    )


def session_rows(stage: Mapping[str, Any], path: Path) -> list[SessionData] | None:
    """A session stage's gatherer: its data, or None while its person record is not written."""
    data = session_data(stage, path)
    return None if data is None else [data]


def base_lengths(stage: Mapping[str, Any], path: Path) -> list[tuple[str, Any]]:
    """A collect stage's gatherer: D_base's ``(task, (mean length, std, demos))``."""
    cfg = stage["config"]
    return [(cfg["collect"]["task"], _lengths(path))] if cfg.get("role") == "base" else []


def base_states(stage: Mapping[str, Any], path: Path) -> list[tuple[str, Any]]:
    """A collect stage's gatherer: D_base's ``(task, first states)``."""
    cfg = stage["config"]
    return [(cfg["collect"]["task"], _first_states(path))] if cfg.get("role") == "base" else []


def fitted_thresholds(stage: Mapping[str, Any], path: Path) -> list[tuple[Any, Any]]:
    """A fit-thresholds stage's gatherer: ``((task, model), the fit)``."""
    cfg = stage["config"]
    return [((cfg["task"], cfg["model"]), _thresholds(path))]


def filter_counts(stage: Mapping[str, Any], path: Path) -> list[FilterCount]:
    """A filter-session stage's gatherer: what the M-filter kept of a naive session."""
    cfg = stage["config"]
    where = {"task": cfg["task"], "model": cfg["model"], "person": cfg["person"]}
    return [FilterCount(**where, **kept_counts(read_header(path)))]


STUDY_FIELDS = ("sessions", "base_lengths", "base_states", "study_thresholds", "session_filters")
"""The report fields an elicitation study gathers (its stage kinds' and its extensions of the
filtering kinds' :attr:`~elicit_jax.pipeline.stage_kind.StageKind.gather` keys)."""


def gather_study(run_dir: str | Path, kinds: StageKinds) -> StudyData:
    """Everything the study report shows, read from ``run_dir``'s finished artifacts by the
    gatherers of ``kinds``."""
    run, rows = gather_fields(run_dir, STUDY_REPORT_STAGE, kinds, STUDY_FIELDS)
    return StudyData(
        **run,
        sessions=tuple(rows["sessions"]),
        base_lengths=dict(rows["base_lengths"]),
        base_states=dict(rows["base_states"]),
        thresholds=dict(rows["study_thresholds"]),
        filters=tuple(rows["session_filters"]),
    )


def _thresholds(path: Path) -> dict[str, Any]:
    """The fitted (λ, η) a study's sessions and M-filter ran under, and how far to trust it."""
    data = read_thresholds_header(path)
    report = dict(data.get("report", {}))
    return {
        **read_thresholds(path).to_json(),
        "method": data.get("method", "fit"),
        "trust": report.get("trust"),
        "balanced_accuracy": report.get("balanced_accuracy"),
    }
