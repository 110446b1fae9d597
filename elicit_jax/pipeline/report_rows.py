"""The rows a filtering or models report is made of, and the labels its tables use.

:class:`ReportData` holds everything a report shows (gathered from a run directory by
:mod:`elicit_jax.pipeline.gather`, or read back from a report folder by
:mod:`elicit_jax.pipeline.evidence`). Every row names the collection it comes from
(``collection``: 0 for a single-collection study; ``[collections]``); a result of named sizes
other than the default (:mod:`elicit_jax.pipeline.sizes`) names them (``sizes``) and carries
them in its task label, as every row of those sizes does.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from elicit_jax.pipeline.findings import Findings

METHOD_LABELS = {
    "base": "Base",
    "naive": "Naive",
    "filtered": "M-Filtered",
    "filtered-episode": "M-Filtered (episodes)",
    "random": "Random filter",
    "longest": "Drop longest",
    "shortest": "Drop shortest",
    "likelihood": "Likelihood-only",
    "novelty": "Novelty-only",
    "filtered-valley": "M-Filtered (valley λ)",
    "deminf": "DemInf",
    "deminf-matched": "DemInf (M's amount)",
    "demo-score": "Demo-SCORE",
    "demo-score-matched": "Demo-SCORE (M's amount)",
    "cupid": "CUPID",
    "cupid-matched": "CUPID (M's amount)",
    "quality": "Quality flags",
    "quality-matched": "Quality flags (M's amount)",
}


@dataclasses.dataclass(frozen=True)
class ResultRow:
    """Success of one trained policy (one seed), at its selected checkpoint."""

    task: str
    model: str
    method: str
    operator: str | None
    seed: int
    success: float
    mean_length: float
    n_rollouts: int
    checkpoint: str
    init_states: str = ""
    study: str = "main"
    point: int | None = None
    selection: str = "reported"
    eval_seeds: tuple[int, ...] = ()
    select_success: float | None = None
    collection: int = 0
    sizes: str = "default"


@dataclasses.dataclass(frozen=True)
class ThresholdRow:
    """A threshold fit and the contrast sets it was fitted on."""

    task: str
    model: str
    lambda_: float
    eta: float
    compatible: str
    incompatible: str
    metrics: Mapping[str, Any]
    collection: int = 0


@dataclasses.dataclass(frozen=True)
class LengthRow:
    """Demonstration lengths of one demo set."""

    task: str
    name: str
    operator: str
    n_episodes: int
    mean_length: float
    std_length: float
    collection: int = 0


@dataclasses.dataclass(frozen=True)
class ConflictRow:
    """How many demos of one collected demo set conflict with the base operator's way,
    measured per demo from its own states (the demos' ``conflicts`` column, recorded by
    ``collect`` on tasks that measure episode traits).

    Attributes:
      role: the set's role: ``base`` (D_base), ``new`` (a D_new), ``holdout`` or
        ``incompatible`` (the contrast sets of the threshold fit).
      require: what the set's collection kept only (``conflicts``, ``no-conflict``: its demos
        were verified as they were collected), or empty.
    """

    task: str
    role: str
    operator: str
    n_demos: int
    n_conflicts: int
    require: str = ""
    collection: int = 0


@dataclasses.dataclass(frozen=True)
class FilterRow:
    """What one filter kept of one D_new."""

    task: str
    model: str
    method: str
    operator: str
    pairs_kept: int
    pairs_total: int
    episodes_kept: int
    episodes_total: int
    note: str = ""
    collection: int = 0


@dataclasses.dataclass(frozen=True)
class CurationRow:
    """Per-demonstration scores of one curation baseline on one D_new."""

    task: str
    model: str | None
    method: str
    operator: str
    scores: tuple[float, ...]
    threshold: float | None
    trusted: bool
    report: Mapping[str, Any]
    collection: int = 0


@dataclasses.dataclass(frozen=True)
class LambdaPoint:
    """One λ of the sensitivity study: point k of the fit's margin range."""

    task: str
    model: str
    point: int
    lambda_: float
    fitted: float
    low: float
    high: float


@dataclasses.dataclass(frozen=True)
class RunReport:
    """What every report of a run shows, whatever its kind (a filtering or models study:
    :class:`ReportData`; an elicitation study:
    :class:`~elicit_jax.pipeline.elicitation.gather.StudyData`), besides its own rows.

    Attributes:
      pipeline, profile, description, spec_text: the definition run.
      run_dir: where it ran.
      results: per trained policy and seed, the success at its chosen checkpoint.
      notes: lines the report states first (training setup, unfinished stages).
      findings: the authors' reading of the run, put first in the report.
      provenance: the run's provenance (code commits, command, versions).
      raw_results: the raw results are kept beside the report (it can be rebuilt).
      rollouts: the per-rollout table ``results`` were computed from (``None``: not kept).
    """

    pipeline: str
    profile: str
    description: str
    run_dir: str
    spec_text: str
    results: tuple[ResultRow, ...]
    notes: tuple[str, ...] = dataclasses.field(default=(), kw_only=True)
    findings: Findings | None = dataclasses.field(default=None, kw_only=True)
    provenance: Mapping[str, Any] = dataclasses.field(default_factory=dict, kw_only=True)
    raw_results: bool = dataclasses.field(default=False, kw_only=True)
    rollouts: Any = dataclasses.field(default=None, kw_only=True, compare=False, repr=False)


@dataclasses.dataclass(frozen=True)
class ReportData(RunReport):
    """Everything a filtering or models report shows."""

    thresholds: tuple[ThresholdRow, ...] = ()
    lengths: tuple[LengthRow, ...] = ()
    conflicts: tuple[ConflictRow, ...] = ()
    filters: tuple[FilterRow, ...] = ()
    curation: tuple[CurationRow, ...] = ()
    heldout: tuple[ResultRow, ...] = ()
    lambda_points: tuple[LambdaPoint, ...] = ()
    maps: tuple[tuple[str, str], ...] = ()
    figures: tuple[tuple[str, str], ...] = ()
    configs: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    versions: Mapping[str, str] = dataclasses.field(default_factory=dict)


ROW_FIELDS = {
    "thresholds": ThresholdRow,
    "lengths": LengthRow,
    "conflicts": ConflictRow,
    "filters": FilterRow,
    "curation": CurationRow,
    "lambda_points": LambdaPoint,
}
"""The :class:`ReportData` fields that hold rows read from the run's stages, and their row type."""
OPTIONAL_ROW_FIELDS = ("conflicts",)
"""Row fields a ``report-data.json`` holds only when they have rows: absent from those kept
before the field existed (and from a run that has none), so those rebuild as they were."""

Table = tuple[list[str], list[list[str]]]


def task_label(task: str, collection: int, several: bool) -> str:
    """A table's task cell: the task, and its collection when the report has several."""
    return f"{task} (collection {collection})" if several else task


def several_collections(rows: Any) -> bool:
    """True when ``rows`` (any rows with a ``collection``) come from more than one collection."""
    return len({r.collection for r in rows}) > 1
