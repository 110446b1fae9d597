"""What each finished stage of a filtering study adds to its report: the gatherers of the
stage kinds (:attr:`~elicit_jax.pipeline.stage_kind.StageKind.gather`), one per report field
of :class:`~elicit_jax.pipeline.report_rows.ReportData` (demonstration lengths, the demos
that conflict, threshold fits and valley rules, filter counts, curation scores, λ points,
maps) and the evaluations' rollouts every study gathers.

Each gatherer takes a stage's record in ``run.json`` and its output path and returns the rows
it adds, each marked with the stage's collection and, for named sizes other than the default
(:mod:`elicit_jax.pipeline.sizes`), with its sizes in the task label
(:func:`~elicit_jax.pipeline.sizes.sized_task`), so every table keeps a run's sizes apart.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import read_header
from elicit_jax.compat.thresholds import (
    Thresholds,
    config_fields,
    pair_from_json,
    read_thresholds,
    read_thresholds_header,
)
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline import report_rows
from elicit_jax.pipeline.evidence import cell_frame
from elicit_jax.pipeline.sizes import DEFAULT_SIZES, sized_task
from elicit_jax.provenance import shown_paths_in


def _sizes(stage: Mapping[str, Any]) -> str:
    """The named sizes ``stage`` was planned at (:data:`DEFAULT_SIZES` when its config has
    none, as every stage of a run without sizes)."""
    return str(stage["config"].get("sizes", DEFAULT_SIZES))


def _mark(stage: Mapping[str, Any], rows: list[Any]) -> list[Any]:
    """``rows`` marked with the collection and the sizes of ``stage``."""
    collection = int(stage["config"].get("collection", 0))
    sizes = _sizes(stage)
    return [
        dataclasses.replace(row, collection=collection, task=sized_task(row.task, sizes))
        for row in rows
    ]


def length_rows(stage: Mapping[str, Any], path: Path) -> list[report_rows.LengthRow]:
    """Per operator of a collected demo set: its number of demos and their mean length."""
    import pyarrow.parquet as pq

    table = pq.read_table(path, columns=["episode", "operator"])
    episode = table.column("episode").to_numpy()
    operator = np.asarray(table.column("operator").to_pylist(), dtype=str)
    _, first, counts = np.unique(episode, return_index=True, return_counts=True)
    rows = []
    for op in dict.fromkeys(operator[first].tolist()):
        lens = counts[operator[first] == op]
        rows.append(
            report_rows.LengthRow(
                task=stage["config"]["collect"]["task"],
                name=Path(stage["output"]).stem,
                operator=op,
                n_episodes=len(lens),
                mean_length=float(lens.mean()),
                std_length=float(lens.std(ddof=1)) if lens.size > 1 else 0.0,
            )
        )
    return _mark(stage, rows)


CONFLICTS = "conflicts"
"""The per-step column of collected demos that says whether the episode conflicts with the
base operator's way (:func:`elicit_jax.sim.collect.trait_columns`; constant within an
episode)."""


def conflict_rows(stage: Mapping[str, Any], path: Path) -> list[report_rows.ConflictRow]:
    """Per operator of a collected demo set whose demos carry the :data:`CONFLICTS` column:
    its number of demos and how many of them conflict; none when the column is absent (a task
    that measures no episode traits).

    Raises:
      ElicitError: the column is not constant within an episode (naming the file).
    """
    import pyarrow.parquet as pq

    if CONFLICTS not in pq.read_schema(path).names:
        return []
    table = pq.read_table(path, columns=["episode", "operator", CONFLICTS])
    episode = table.column("episode").to_numpy()
    operator = np.asarray(table.column("operator").to_pylist(), dtype=str)
    flags = np.asarray(table.column(CONFLICTS).to_pylist(), dtype=bool)
    ids, first, inverse = np.unique(episode, return_index=True, return_inverse=True)
    varies = np.flatnonzero(np.bincount(inverse, flags, len(ids)) % np.bincount(inverse))
    if varies.size:
        raise ElicitError(
            f"column '{CONFLICTS}' is not constant within episode {ids[varies[0]]}", path
        )
    cfg = stage["config"]
    rows = []
    for op in dict.fromkeys(operator[first].tolist()):
        mine = flags[first][operator[first] == op]
        rows.append(
            report_rows.ConflictRow(
                task=cfg["collect"]["task"],
                role=str(cfg.get("role", "")),
                operator=op,
                n_demos=int(mine.size),
                n_conflicts=int(mine.sum()),
                require=str(cfg["collect"].get("require", "")),
            )
        )
    return _mark(stage, rows)


def _shown(value: Any, run_dir: Path) -> Any:
    """``value`` with the absolute paths in its strings shown relative to ``run_dir``
    (:func:`~elicit_jax.provenance.shown_path`): a report names no folder of the machine."""
    if isinstance(value, str):
        return shown_paths_in(value, run_dir)
    if isinstance(value, Mapping):
        return {k: _shown(v, run_dir) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(_shown(v, run_dir) for v in value)
    return value


def _row_fields(t: Thresholds) -> dict[str, float]:
    """A report row's ``lambda_`` and ``eta`` (the field names committed report data keeps)."""
    return config_fields(t, key="lambda_")  # type: ignore[return-value]


def _threshold_row(stage: Mapping[str, Any], path: Path) -> report_rows.ThresholdRow:
    data = read_thresholds_header(path)
    run_dir = path.parents[len(Path(stage["output"]).parts) - 1]
    report = _shown(dict(data.get("report", {})), run_dir)
    cfg = stage["config"]
    method = data.get("method", "fit")
    report.setdefault("margin", report.get("margin_quantile"))
    return report_rows.ThresholdRow(
        task=cfg["task"],
        model=cfg["model"],
        **_row_fields(read_thresholds(path)),
        compatible=f"{report.get('n_compatible', '?')} held-out demos of "
        f"'{cfg['compatible_operator']}' (collect seed {cfg['holdout_seed']})",
        incompatible=f"{report.get('n_incompatible', '?')} demos of "
        f"'{cfg['incompatible_operator']}' (collect seed {cfg['incompatible_seed']}, disjoint "
        "from every D_new)" + ("" if method == "fit" else "; thresholds set by hand, not fitted"),
        metrics=report,
    )


def _valley_row(stage: Mapping[str, Any], path: Path) -> report_rows.ThresholdRow:
    rep = dict(read_thresholds_header(path).get("report", {}))
    lo, hi = rep.get("lambda_range", (math.nan, math.nan))
    note = rep.get("note") or (
        f"density of familiar new pairs {rep.get('density_ratio_chosen_to_fitted', math.nan):.2g}"
        f"× that at the fitted λ; {100 * rep.get('familiar_share_between', 0):.1f}% of them "
        "lie between the two"
    )
    return report_rows.ThresholdRow(
        task=stage["config"]["task"],
        model=stage["config"]["model"],
        **_row_fields(read_thresholds(path)),
        compatible=f"valley rule: λ moved from the fitted {rep.get('fitted_lambda', math.nan):.4g} "
        f"to the sparsest point of D_new's familiar pairs inside the margin {lo:.4g} .. {hi:.4g}",
        incompatible=note,
        metrics={},
    )


def kept_counts(header: Mapping[str, Any]) -> dict[str, int]:
    """What a filter-like stage kept of its input, from its output's header
    (:func:`~elicit_jax.pipeline.stages_compat.write_filter_header`): pairs and episodes
    kept, of how many."""
    return {
        "pairs_kept": int(header["pairs_in"]) - int(header["pairs_dropped"]),
        "pairs_total": int(header["pairs_in"]),
        "episodes_kept": int(header["episodes_out"]),
        "episodes_total": int(header["episodes_in"]),
    }


def _filter_row(stage: Mapping[str, Any], path: Path) -> report_rows.FilterRow:
    h = read_header(path)
    cfg = stage["config"]
    method = cfg["method"]
    if "/heldout/" in stage["id"]:  # the λ-sensitivity study's filters
        applied = pair_from_json(h["thresholds"], path)[0]
        method = f"M-Filtered at λ = {applied:.4g} (sensitivity)"
    return report_rows.FilterRow(
        task=cfg["task"],
        model=cfg["model"],
        method=method,
        operator=cfg["operator"],
        **kept_counts(h),
        note="" if h.get("trusted", True) else "no signal: kept every demo",
    )


def _curation_row(stage: Mapping[str, Any], path: Path) -> report_rows.CurationRow:
    from elicit_jax.curation.episodes import read_episode_scores

    scores = read_episode_scores(path)
    cfg = stage["config"]
    report = dict(scores.report)
    if "deminf" in cfg:
        report["drop_fraction"] = cfg["deminf"].get("drop_fraction")
    return report_rows.CurationRow(
        task=cfg["task"],
        model=cfg.get("model"),
        method=scores.method,
        operator=cfg["operator"],
        scores=tuple(float(v) for v in scores.score),
        threshold=scores.threshold,
        trusted=scores.trusted,
        report=report,
    )


def _lambda_point(stage: Mapping[str, Any], path: Path) -> report_rows.LambdaPoint:
    rep = read_thresholds_header(path).get("report", {})
    lo, hi = rep["lambda_range"]
    cfg = stage["config"]
    return report_rows.LambdaPoint(
        task=cfg["task"],
        model=cfg["model"],
        point=int(rep["point"]),
        lambda_=read_thresholds(path).lam,
        fitted=float(rep["fitted_lambda"]),
        low=float(lo),
        high=float(hi),
    )


def rollout_frames(stage: Mapping[str, Any], path: Path) -> list[Any]:
    """An evaluation's per-rollout table (:func:`~elicit_jax.pipeline.evidence.cell_frame`),
    from which every study computes its results."""
    return [cell_frame(stage["config"], path)]


def threshold_rows(stage: Mapping[str, Any], path: Path) -> list[report_rows.ThresholdRow]:
    """A threshold fit: the fitted (λ, η), the contrast sets it was fitted on, its metrics."""
    return _mark(stage, [_threshold_row(stage, path)])


def valley_rows(stage: Mapping[str, Any], path: Path) -> list[report_rows.ThresholdRow]:
    """The valley rule's (λ, η): where it moved λ, and why."""
    return _mark(stage, [_valley_row(stage, path)])


def filter_rows(stage: Mapping[str, Any], path: Path) -> list[report_rows.FilterRow]:
    """A filter's (or a curation cut's) counts: pairs and episodes kept, of how many."""
    return _mark(stage, [_filter_row(stage, path)])


def curation_rows(stage: Mapping[str, Any], path: Path) -> list[report_rows.CurationRow]:
    """A curation method's per-demonstration scores and its own cut."""
    return _mark(stage, [_curation_row(stage, path)])


def lambda_points(stage: Mapping[str, Any], path: Path) -> list[report_rows.LambdaPoint]:
    """One λ point of the sensitivity study (marked with its sizes only: the study runs on
    collection 0)."""
    point = _lambda_point(stage, path)
    return [dataclasses.replace(point, task=sized_task(point.task, _sizes(stage)))]


def map_figures(stage: Mapping[str, Any], path: Path) -> list[tuple[str, str]]:
    """A compatibility map: its caption and file."""
    cfg = stage["config"]
    collection = int(cfg.get("collection", 0))
    task = sized_task(cfg["task"], _sizes(stage))
    where = f"{task}, {cfg['model']}" + (f", collection {collection}" * bool(collection))
    return [(f"{where}: compatibility map per operator", str(path))]
