"""An elicitation study's raw results, kept in its report folder so the report can be rebuilt.

Beside the per-rollout table every study report keeps (``rollouts.parquet``,
:mod:`elicit_jax.pipeline.evidence`), a study's ``report-data.json`` holds the rest of
:class:`~elicit_jax.pipeline.elicitation.gather.StudyData`: each session's per-episode
summaries and the person's record, D_base's lengths and first states (to compare styles on),
the thresholds, the M-filter counts, stage configs, versions and the run's provenance.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from elicit_jax.artifact import dumps, make_header
from elicit_jax.pipeline.elicitation.gather import FilterCount, SessionData, StudyData
from elicit_jax.pipeline.evidence import result_rows_of

STUDY_DATA_KIND = "study-report-data"
"""The artifact kind of an elicitation study report's ``report-data.json``."""


def study_to_json(data: StudyData) -> dict[str, Any]:
    """``data`` without its results and rollouts (they live in the rollout table)."""
    skip = ("results", "rollouts", "findings", "base_states", "thresholds", "raw_results")
    body = {f.name: getattr(data, f.name) for f in dataclasses.fields(data) if f.name not in skip}
    body["thresholds"] = [[t, m, dict(v)] for (t, m), v in data.thresholds.items()]
    body["base_states"] = {
        task: [{"dtype": str(np.asarray(s).dtype), "values": np.asarray(s)} for s in states]
        for task, states in data.base_states.items()
    }
    seeds = sorted({r.seed for r in data.results})
    return make_header(STUDY_DATA_KIND, 1, seed=seeds[0] if seeds else None, data=body)


def study_from_json(header: Mapping[str, Any], rollouts: Any, folder: Any = None) -> StudyData:
    """The inverse of :func:`study_to_json`, results recomputed from ``rollouts`` (``folder``,
    the report folder read, is not needed: a study's figures are drawn anew)."""
    body = dict(header["data"])
    return StudyData(
        **{
            **body,
            "results": tuple(result_rows_of(rollouts)) if len(rollouts) else (),
            "sessions": tuple(
                SessionData(**{**s, "rows": tuple(s["rows"])}) for s in body["sessions"]
            ),
            "base_lengths": {k: tuple(v) for k, v in body["base_lengths"].items()},
            "base_states": {
                task: tuple(np.asarray(s["values"], dtype=s["dtype"]) for s in states)
                for task, states in body["base_states"].items()
            },
            "thresholds": {(t, m): v for t, m, v in body["thresholds"]},
            "filters": tuple(FilterCount(**f) for f in body["filters"]),
            "notes": tuple(body["notes"]),
            "rollouts": rollouts,
        }
    )


def round_trip_study(data: StudyData) -> StudyData:
    """``data`` as a rebuild will read it back: rendering this makes the first report and
    its rebuilds byte-identical."""
    back = study_from_json(json.loads(dumps(study_to_json(data))), data.rollouts)
    return dataclasses.replace(back, findings=data.findings)
