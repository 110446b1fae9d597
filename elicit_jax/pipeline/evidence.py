"""The raw results a report is made from, kept in the report folder so the report can be rebuilt.

A study's report folder holds, beside ``report.md``:

* ``rollouts.parquet`` — one row per evaluation rollout: the policy cell (collection, task,
  model, method, operator, study, λ point, sizes), training seed, checkpoint, evaluation seed
  and its role (``select``: rollouts the checkpoint is chosen on; ``report``: rollouts whose
  success is reported), rollout index, initial-state seed, success and length;
* ``report-data.json`` — everything else the report shows (threshold fits, filter counts,
  curation scores, demonstration lengths, the demos that conflict, stage configs, versions,
  the run's provenance).

``elicit-jax report --rebuild DIR`` (:func:`elicit_jax.pipeline.run.rebuild_report`; an
elicitation study: :mod:`elicit_jax.pipeline.elicitation.evidence`) recomputes every table, interval
and figure from those two files (and the maps and findings beside them) alone.

Checkpoint selection (:data:`SELECTIONS`): ``heldout`` (the default of new runs) chooses each
training seed's checkpoint on the rollouts of one evaluation seed and reports the success of
that checkpoint on another seed's rollouts; ``reported`` is the paper's rule, the best
checkpoint on the very rollouts that are reported — a maximum over noisy checkpoints, biased
upwards.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.artifact import dumps, read_artifact, read_header
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.report_rows import (
    OPTIONAL_ROW_FIELDS,
    ROW_FIELDS,
    ReportData,
    ResultRow,
)
from elicit_jax.pipeline.sizes import DEFAULT_SIZES, sized_task

ROLLOUTS_FILE = "rollouts.parquet"
DATA_FILE = "report-data.json"
ROLLOUTS_KIND = "study-rollouts"
DATA_KIND = "report-data"
SELECTIONS = ("heldout", "reported")
SELECT_SEED_OFFSET = 100
"""Default selection seed of held-out selection: the reported evaluation seed + this."""
CELL_KEYS = ("collection", "task", "model", "method", "operator", "study", "point", "sizes")
SELECTION_TEXT = {
    "heldout": "**Checkpoint selection: held-out.** Each training seed's checkpoint is chosen "
    "on the rollouts of one evaluation seed (initial states) and its success is reported on "
    "the rollouts of another seed, so the maximum over checkpoints does not inflate the "
    "reported success",
    "reported": "**Checkpoint selection: best on the reported rollouts** (the paper's rule). "
    "Each training seed's checkpoint is the best on the very rollouts whose success is "
    "reported: a maximum over noisy checkpoints, **biased upwards**, and the intervals "
    "ignore it",
    "single": "**Checkpoint: the only one evaluated.** Each training seed was evaluated at a "
    'single checkpoint (e.g. `[evaluate] checkpoints = ["final"]`), so nothing was chosen '
    "and no maximum over checkpoints inflates the reported success",
}
"""How the report states each rule; ``single`` is not a setting but what either setting
amounts to when a cell's seeds were evaluated at one checkpoint only."""

ROLLOUT_COLUMNS = [
    *CELL_KEYS,
    "selection",
    "training_seed",
    "checkpoint",
    "eval_seed",
    "role",
    "rollout",
    "init_seed",
    "success",
    "length",
]
"""The columns of a report's ``rollouts.parquet``, in order."""


def run_provenance(manifest: Mapping[str, Any], evaluations: Sequence[Path]) -> dict[str, Any]:
    """The run's provenance (its manifest's, i.e. the last ``pipeline run``), plus the code
    commits that made its finished ``evaluations`` (``result_commits``: commit -> count), which
    differ when cached stages carried the run across code versions."""
    from elicit_jax.artifact import PROVENANCE_KEY

    commits: dict[str, int] = {}
    for path in evaluations:
        made = read_header(path).get(PROVENANCE_KEY, {})
        commit = str(made.get("commit", "unknown")) + ("+dirty" if made.get("dirty") else "")
        commits[commit] = commits.get(commit, 0) + 1
    return {**manifest.get(PROVENANCE_KEY, {}), "result_commits": commits}


def selection_meta(meta: Mapping[str, Any], seed: int) -> dict[str, Any]:
    """The checkpoint-selection keys of an evaluate stage, validated (default: held-out on
    evaluation seed ``seed + 100``)."""
    selection = str(meta.get("selection", "heldout"))
    if selection not in SELECTIONS:
        raise ElicitError(
            f"[evaluate] selection must be one of {', '.join(SELECTIONS)}, got {selection!r}"
        )
    if selection == "reported":
        return {"selection": selection}
    select_seed = int(meta.get("select_seed", seed + SELECT_SEED_OFFSET))
    if select_seed == seed:
        raise ElicitError(
            f"[evaluate] select_seed must differ from the reported evaluation seed ({seed}): "
            "held-out selection needs other initial states"
        )
    return {"selection": selection, "select_seed": select_seed}


def cell_frame(config: Mapping[str, Any], path: str | Path) -> Any:
    """One evaluate stage's rollouts as rows of the study's rollout table."""
    import pyarrow.parquet as pq

    frame = pq.read_table(path).to_pandas()
    report_seed = int(config["evaluate"]["seed"])
    if "eval_seed" not in frame:  # made before held-out selection: one evaluation seed
        frame = frame.assign(eval_seed=np.int32(report_seed))
    selection = config.get("selection", "reported")
    role = np.where(frame["eval_seed"].to_numpy() == report_seed, "report", "select")
    point = config.get("point")
    return frame.assign(
        collection=np.int32(config.get("collection", 0)),
        task=config["evaluate"]["task"],
        model=config["model"],
        method=config["method"],
        operator=config.get("operator") or "",
        study=str(config.get("study", "main")),
        point=np.int32(-1 if point is None else point),
        sizes=str(config.get("sizes", DEFAULT_SIZES)),
        selection=selection,
        role=role,
        training_seed=frame["seed"].astype(np.int32),
        eval_seed=frame["eval_seed"].astype(np.int32),
        length=frame["length"].astype(np.int32),
    )[ROLLOUT_COLUMNS]


def empty_rollouts() -> Any:
    """A rollout table with no rows (a run whose evaluations have not finished)."""
    import pandas as pd

    return pd.DataFrame(
        {
            **{k: pd.Series(dtype=str) for k in CELL_KEYS if k not in ("point", "collection")},
            "collection": pd.Series(dtype=np.int32),
            "point": pd.Series(dtype=np.int32),
            "selection": pd.Series(dtype=str),
            "training_seed": pd.Series(dtype=np.int32),
            "checkpoint": pd.Series(dtype=str),
            "eval_seed": pd.Series(dtype=np.int32),
            "role": pd.Series(dtype=str),
            "rollout": pd.Series(dtype=np.int32),
            "init_seed": pd.Series(dtype=np.int64),
            "success": pd.Series(dtype=bool),
            "length": pd.Series(dtype=np.int32),
        }
    )[ROLLOUT_COLUMNS]


def init_states_id(init_seeds: np.ndarray) -> str:
    """A short fingerprint of the ordered initial-state seeds of a set of rollouts (paired
    comparisons require equal fingerprints)."""
    import hashlib

    return hashlib.sha256(np.asarray(init_seeds, np.int64).tobytes()).hexdigest()[:16]


def _per_checkpoint(frame: Any) -> Any:
    return (
        frame.groupby("checkpoint", sort=False)
        .agg(success=("success", "mean"), length=("length", "mean"), n=("success", "size"))
        .reset_index()
    )


def choose_checkpoint(rollouts: Any) -> tuple[str, float]:
    """The checkpoint with the highest success among one training seed's rollouts, and that
    success; ties go to the first checkpoint in the rollouts' order (the earliest saved). The
    evaluate stage and the report choose with this one rule."""
    per = _per_checkpoint(rollouts)
    best = per.loc[per["success"].idxmax()]
    return str(best["checkpoint"]), float(best["success"])


def _cell_rows(cell: Any) -> list[ResultRow]:
    """Per training seed of one cell: the chosen checkpoint and its reported success."""
    first = cell.iloc[0]
    sizes = str(first["sizes"])
    rows = []
    for seed, g in cell.groupby("training_seed", sort=True):
        report = g[g["role"] == "report"]
        choose = g[g["role"] == "select"] if first["selection"] == "heldout" else report
        if choose.empty:
            raise ElicitError(
                f"held-out selection but no selection rollouts for {first['method']} seed {seed}"
            )
        checkpoint, select_success = choose_checkpoint(choose)
        single = choose["checkpoint"].nunique() == 1 and report["checkpoint"].nunique() == 1
        shown = _per_checkpoint(report).set_index("checkpoint").loc[checkpoint]
        reported = report[report["checkpoint"] == checkpoint]
        rows.append(
            ResultRow(
                task=sized_task(str(first["task"]), sizes),
                model=str(first["model"]),
                method=str(first["method"]),
                operator=str(first["operator"]) or None,
                seed=int(seed),
                success=float(shown["success"]),
                mean_length=float(shown["length"]),
                n_rollouts=int(shown["n"]),
                checkpoint=checkpoint,
                init_states=init_states_id(reported["init_seed"].to_numpy()),
                study=str(first["study"]),
                point=None if int(first["point"]) < 0 else int(first["point"]),
                selection="single" if single else str(first["selection"]),
                eval_seeds=tuple(sorted({int(s) for s in g["eval_seed"]})),
                select_success=select_success,
                collection=int(first["collection"]),
                sizes=sizes,
            )
        )
    return rows


def result_rows_of(frame: Any) -> list[ResultRow]:
    """Result rows of a study's rollout table, cell by cell in the order they appear."""
    rows: list[ResultRow] = []
    for _, cell in frame.groupby(list(CELL_KEYS), sort=False, dropna=False):
        rows += _cell_rows(cell)
    return rows


def selection_lines(results: Sequence[ResultRow]) -> list[str]:
    """The report's statement of how checkpoints were chosen (one line per rule used)."""
    out = []
    for rule in dict.fromkeys(r.selection for r in results):
        mine = [r for r in results if r.selection == rule]
        seeds = sorted({s for r in mine for s in r.eval_seeds})
        out.append(
            f"{SELECTION_TEXT[rule]} (evaluation seeds {seeds}; {len(mine)} trained policies)."
        )
    return out


def _rows(cls: type, items: Sequence[Mapping[str, Any]], tuples: tuple[str, ...] = ()) -> tuple:
    return tuple(
        cls(**{k: tuple(v) if k in tuples else v for k, v in item.items()}) for item in items
    )


def data_to_json(data: ReportData) -> dict[str, Any]:
    """``data`` without its results (they live in the rollout table), as a JSON header (an
    optional row field without rows left out: :data:`OPTIONAL_ROW_FIELDS`)."""
    from elicit_jax.artifact import make_header

    body = {
        f.name: getattr(data, f.name)
        for f in dataclasses.fields(data)
        if f.name not in ("results", "heldout", "figures", "findings", "maps", "rollouts")
        and not (f.name in OPTIONAL_ROW_FIELDS and not getattr(data, f.name))
    }
    body["maps"] = [[caption, f"maps/{Path(png).name}"] for caption, png in data.maps]
    seeds = sorted({r.seed for r in (*data.results, *data.heldout)})
    return make_header(DATA_KIND, 1, seed=seeds[0] if seeds else None, data=body)


def data_from_json(header: Mapping[str, Any], folder: Path) -> ReportData:
    """The inverse of :func:`data_to_json` (maps resolved inside ``folder``; an optional row
    field it does not hold has no rows)."""
    body = dict(header["data"])
    for name in OPTIONAL_ROW_FIELDS:
        body.setdefault(name, [])
    return ReportData(
        **{
            **body,
            **{name: _rows(row, body[name], ("scores",)) for name, row in ROW_FIELDS.items()},
            "maps": tuple((c, str(folder / rel)) for c, rel in body["maps"]),
            "notes": tuple(body["notes"]),
            "results": (),
        }
    )


def write_rollouts_table(path: Path, rollouts: Any, pipeline: str, profile: str) -> None:
    """Write a study's per-rollout table (``rollouts.parquet``) with its header."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from elicit_jax.artifact import HEADER_KEY, make_header

    seeds = sorted({int(s) for s in rollouts["training_seed"]})
    header = make_header(
        ROLLOUTS_KIND,
        1,
        config={"pipeline": pipeline, "profile": profile},
        seed=seeds[0] if seeds else None,
        training_seeds=seeds,
        eval_seeds=sorted({int(s) for s in rollouts["eval_seed"]}),
        n_rows=len(rollouts),
        columns=list(rollouts.columns),
    )
    table = pa.Table.from_pandas(rollouts, preserve_index=False)
    table = table.replace_schema_metadata({HEADER_KEY: dumps(header).encode()})
    pq.write_table(table, path, compression="zstd")


def round_trip(data: ReportData) -> ReportData:
    """``data`` as a rebuild will read it back (JSON turns tuples into lists): rendering this
    makes the first report and its rebuilds byte-identical."""
    import json

    back = data_from_json(json.loads(dumps(data_to_json(data))), Path("."))
    kept = ("maps", "results", "heldout", "findings", "rollouts")
    return dataclasses.replace(back, **{k: getattr(data, k) for k in kept})


def read_raw(folder: str | Path, data_kinds: Sequence[str]) -> tuple[dict[str, Any], Any]:
    """A report folder's ``report-data.json`` header (of one of the ``data_kinds``: the study
    kinds') and rollout table, or a one-line error naming what is missing."""
    import pyarrow.parquet as pq

    folder = Path(folder)
    for name in (ROLLOUTS_FILE, DATA_FILE):
        if not (folder / name).is_file():
            raise ElicitError(
                f"cannot rebuild: no {name} here (reports made before elicit-jax kept raw "
                "results cannot be rebuilt; re-run the study)",
                folder,
            )
    header = read_artifact(folder / DATA_FILE, tuple(data_kinds), 1)
    read_artifact(folder / ROLLOUTS_FILE, ROLLOUTS_KIND, 1, what="a study rollout table")
    frame = pq.read_table(folder / ROLLOUTS_FILE).to_pandas()
    if "sizes" not in frame:  # kept before named sizes: the default sizes
        frame = frame.assign(sizes=DEFAULT_SIZES)
    return header, frame


def report_data_of(header: Mapping[str, Any], frame: Any, folder: Path) -> ReportData:
    """A filtering or models report's data from its folder's raw results."""
    if "collection" not in frame:  # kept before [collections]
        frame.insert(0, "collection", np.int32(0))
    results = result_rows_of(frame) if len(frame) else []
    return dataclasses.replace(
        data_from_json(header, folder),
        results=tuple(r for r in results if r.study == "main"),
        heldout=tuple(r for r in results if r.study != "main"),
        rollouts=frame,
    )
