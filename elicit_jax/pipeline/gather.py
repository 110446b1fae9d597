"""Gather a run directory's artifacts into :class:`~elicit_jax.pipeline.report_rows.ReportData`
(:func:`walk_run`: what every report kind reads of a run directory).

Reads the run manifest (``run.json``: the definition and every stage) and, for each finished
stage, its artifact: evaluations (success per seed), threshold fits, filter counts, maps and
the demonstration sets' lengths. Stages that have not finished yet are listed in a note, so a
report of a partial run is still correct about what it shows.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import read_artifact, read_header
from elicit_jax.compat.thresholds import (
    Thresholds,
    config_fields,
    pair_from_json,
    read_thresholds,
    read_thresholds_header,
)
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline import report_rows
from elicit_jax.pipeline.evidence import (
    cell_frame,
    empty_rollouts,
    result_rows_of,
    run_provenance,
)
from elicit_jax.pipeline.report_rows import ReportData, ResultRow
from elicit_jax.provenance import shown_path, shown_paths_in

MANIFEST = "run.json"
MANIFEST_KIND = "pipeline-run"


def read_manifest(run_dir: str | Path) -> dict[str, Any]:
    """The run manifest, or a one-line error when ``run_dir`` is not a pipeline run."""
    path = Path(run_dir) / MANIFEST
    if not path.exists():
        raise ElicitError(f"not a pipeline run directory (no {MANIFEST})", run_dir)
    return read_artifact(path, MANIFEST_KIND, 1, what="a pipeline run")


def _length_rows(stage: Mapping[str, Any], path: Path) -> list[report_rows.LengthRow]:
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
    return rows


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


def result_rows(config: Mapping[str, Any], path: Path) -> list[ResultRow]:
    """Per training seed: success rate and mean rollout length of its chosen checkpoint.

    The chosen checkpoint has the highest success over the selection rollouts (held-out
    selection: another evaluation seed's; the paper's rule: the reported rollouts themselves;
    ties go to the earliest saved); see :mod:`elicit_jax.pipeline.evidence`.
    """
    return result_rows_of(cell_frame(config, path))


def training_note(train: Mapping[str, Any]) -> str:
    """One line per distinct training setup (model, sizes, epochs), as the report states it."""
    setups = {}
    for cfg in train.values():
        t = cfg["train"]
        key = (
            t["model"],
            tuple(t["hidden"]),
            t["ensemble_size"],
            t["epochs"],
            t["checkpoint_every"],
            t["batch_size"],
            t["lr"],
        )
        setups[key] = None
    parts = [
        f"{m}: {e} member(s) × hidden {list(h)}, {ep} epochs (checkpoint every {ck}), "
        f"batch {b}, lr {lr:g}"
        for m, h, e, ep, ck, b, lr in setups
    ]
    return (
        "Training: " + "; ".join(parts) + ". The paper: 5 × [1024, 1024], 1000 epochs, every 200."
    )


def _gather_stage(stage: Mapping[str, Any], path: Path, rows: dict[str, list]) -> None:
    """Add what one finished stage (not an evaluation) contributes to the report's ``rows``,
    each row marked with the stage's collection."""
    kind, cfg = stage["kind"], stage["config"]
    collection = int(cfg.get("collection", 0))

    def mark(row: Any) -> Any:
        return dataclasses.replace(row, collection=collection)

    if kind == "collect":
        rows["lengths"] += [mark(r) for r in _length_rows(stage, path)]
    elif kind == "fit-thresholds":
        rows["thresholds"].append(mark(_threshold_row(stage, path)))
    elif kind == "lambda-valley":
        rows["thresholds"].append(mark(_valley_row(stage, path)))
    elif kind in ("filter", "curate"):
        rows["filters"].append(mark(_filter_row(stage, path)))
    elif kind in ("deminf", "demo-score", "cupid", "quality"):
        rows["curation"].append(mark(_curation_row(stage, path)))
    elif kind == "lambda-point":
        rows["lambda_points"].append(_lambda_point(stage, path))
    elif kind == "map":
        where = f"{cfg['task']}, {cfg['model']}" + (f", collection {collection}" * bool(collection))
        rows["maps"].append((f"{where}: compatibility map per operator", str(path)))


def walk_run(
    run_dir: str | Path, report_kind: str, take: Callable[[Mapping[str, Any], Path], bool]
) -> dict[str, Any]:
    """Read a run directory the way every report kind does: its manifest, every stage's
    config, every finished evaluation's rollouts; ``take(stage, path)`` reads what any other
    finished stage (not the ``report_kind`` stage) contributes, and returns False when its
    output is not complete yet.

    Returns:
      The fields every report has (:class:`~elicit_jax.pipeline.report_rows.RunReport`:
      definition, run directory, ``results`` of every finished evaluation, ``rollouts``,
      notes, provenance) and the stage ``configs`` and library ``versions``.
    """
    import pandas as pd

    run_dir = Path(run_dir)
    manifest = read_manifest(run_dir)
    head = manifest["config"]
    frames = []
    configs: dict[str, dict[str, Any]] = {}
    missing = []
    for stage in manifest["stages"]:
        path = run_dir / stage["output"]
        configs.setdefault(stage["kind"], {})[stage["id"]] = stage["config"]
        if stage["kind"] == report_kind:
            continue
        if not path.exists():
            missing.append(stage["id"])
        elif stage["kind"] == "evaluate":
            frames.append(cell_frame(stage["config"], path))
        elif not take(stage, path):
            missing.append(stage["id"])
    notes = [training_note(configs["train"])] if configs.get("train") else []
    if missing:
        notes.append(
            f"{len(missing)} stage(s) have not finished, so their results are absent: "
            + ", ".join(missing[:8])
            + (" …" if len(missing) > 8 else "")
        )
    rollouts = pd.concat(frames, ignore_index=True) if frames else empty_rollouts()
    return {
        "pipeline": head["pipeline"],
        "profile": head["profile"],
        "description": head.get("description", ""),
        "run_dir": shown_path(run_dir),
        "spec_text": head.get("spec_text", ""),
        "results": tuple(result_rows_of(rollouts)) if frames else (),
        "rollouts": rollouts,
        "configs": configs,
        "versions": manifest.get("versions", {}),
        "notes": tuple(notes),
        "provenance": run_provenance(manifest, run_dir),
    }


def gather(run_dir: str | Path) -> ReportData:
    """Everything the report shows, read from ``run_dir``'s finished artifacts, with the
    study's per-rollout table the results were computed from (``rollouts``:
    :func:`elicit_jax.pipeline.evidence.cell_frame` rows of every finished evaluation)."""
    rows: dict[str, list] = {name: [] for name in (*report_rows.ROW_FIELDS, "maps")}

    def take(stage: Mapping[str, Any], path: Path) -> bool:
        _gather_stage(stage, path, rows)
        return True

    run = walk_run(run_dir, "report", take)
    results = run.pop("results")
    return ReportData(
        **run,
        results=tuple(r for r in results if r.study == "main"),
        heldout=tuple(r for r in results if r.study != "main"),
        **{name: tuple(found) for name, found in rows.items()},
    )
