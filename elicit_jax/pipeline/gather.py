"""Gather a run directory's artifacts into a study's report data (:func:`gather_fields`: what
every study kind reads of a run directory; :func:`gather`: a filtering study's
:class:`~elicit_jax.pipeline.report_rows.ReportData`).

Reads the run manifest (``run.json``: the definition and every stage) and, for each finished
stage, its artifact, by its stage kind's gatherers: evaluations (success per seed), threshold
fits, filter counts, maps and the demonstration sets' lengths (:mod:`.gather_rows`). Stages
that have not finished yet are listed in a note, so a report of a partial run is still correct
about what it shows.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from elicit_jax.artifact import read_artifact
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline import report_rows
from elicit_jax.pipeline.evidence import (
    cell_frame,
    empty_rollouts,
    result_rows_of,
    run_provenance,
)
from elicit_jax.pipeline.report_rows import ReportData, ResultRow
from elicit_jax.pipeline.stage_kind import StageKinds
from elicit_jax.provenance import shown_path

MANIFEST = "run.json"
MANIFEST_KIND = "pipeline-run"
REPORT_STAGE = "report"
"""The stage kind of a filtering study's report stage."""


def read_manifest(run_dir: str | Path) -> dict[str, Any]:
    """The run manifest, or a one-line error when ``run_dir`` is not a pipeline run."""
    path = Path(run_dir) / MANIFEST
    if not path.exists():
        raise ElicitError(f"not a pipeline run directory (no {MANIFEST})", run_dir)
    return read_artifact(path, MANIFEST_KIND, 1, what="a pipeline run")


def result_rows(config: Mapping[str, Any], path: Path) -> list[ResultRow]:
    """Per training seed: success rate and mean rollout length of its chosen checkpoint.

    The chosen checkpoint has the highest success over the selection rollouts (held-out
    selection: another evaluation seed's; the paper's rule: the reported rollouts themselves;
    ties go to the earliest saved); see :mod:`elicit_jax.pipeline.evidence`.
    """
    return result_rows_of(cell_frame(config, path))


SCORER_METHOD = "scorer"
"""The ``method`` a scorer's train stage records
(:func:`elicit_jax.pipeline.plan_cell.scorer_stage`), by which the report tells it apart."""


def _setup(t: Mapping[str, Any]) -> tuple[Any, ...]:
    """What the report states of one training config: model, sizes, epochs, batch, lr."""
    return (
        t["model"],
        tuple(t["hidden"]),
        t["ensemble_size"],
        t["epochs"],
        t["checkpoint_every"],
        t["batch_size"],
        t["lr"],
    )


def _describe(setup: tuple[Any, ...]) -> str:
    m, h, e, ep, ck, b, lr = setup
    return (
        f"{m}: {e} member(s) × hidden {list(h)}, {ep} epochs (checkpoint every {ck}), "
        f"batch {b}, lr {lr:g}"
    )


def training_note(train: Mapping[str, Any]) -> str:
    """One line per distinct training setup (model, sizes, epochs), as the report states it;
    then, when a scorer (``[scorer]``) was trained with another setup than every compared
    policy, the scorer's, with its training profile and seed."""
    setups: dict[tuple[Any, ...], None] = {}
    scorers: dict[tuple[Any, ...], None] = {}
    for cfg in train.values():
        if cfg.get("method") == SCORER_METHOD:
            seeds = tuple(cfg["train"]["seeds"])
            scorers[(_setup(cfg["train"]), cfg.get("profile"), seeds)] = None
        else:
            setups[_setup(cfg["train"])] = None
    parts = [_describe(s) for s in setups]
    paper = "The paper: 5 × [1024, 1024], 1000 epochs, every 200."
    line = "Training: " + "; ".join(parts) + ". " + paper
    own = [
        f"{_describe(s)}, training profile {p}, seed {','.join(map(str, seeds))}"
        for s, p, seeds in scorers
        if s not in setups
    ]
    if own:
        line += (
            " Scoring (the contrast sets and every D_new) by a policy of its own trained on "
            "D_base, not the base policy: " + "; ".join(own) + "."
        )
    return line


ROLLOUTS = "rollouts"
"""The report field every study gathers: the per-rollout tables of its finished evaluations
(the evaluate kind's gatherer), from which its ``results`` are computed."""


def gather_fields(
    run_dir: str | Path, report_kind: str, kinds: StageKinds, fields: tuple[str, ...]
) -> tuple[dict[str, Any], dict[str, list[Any]]]:
    """Read a run directory the way every study kind's report does: its manifest, every
    stage's config, and each finished stage (not the ``report_kind`` stage) by its kind's
    gatherers (:attr:`~elicit_jax.pipeline.stage_kind.StageKind.gather`) into the report
    ``fields`` the study has and :data:`ROLLOUTS` (the gatherers of other fields are not
    called). A stage whose output is missing, or whose gatherer finds it incomplete, is
    listed in a note as not finished.

    Returns:
      The fields every report has (:class:`~elicit_jax.pipeline.report_rows.RunReport`:
      definition, run directory, ``results`` of every finished evaluation, ``rollouts``,
      notes, provenance) and the stage ``configs`` and library ``versions``; and per report
      field the items its stages added, in stage order.
    """
    import pandas as pd

    run_dir = Path(run_dir)
    manifest = read_manifest(run_dir)
    head = manifest["config"]
    rows: dict[str, list[Any]] = {name: [] for name in (ROLLOUTS, *fields)}
    configs: dict[str, dict[str, Any]] = {}
    missing, evaluations = [], []
    for stage in manifest["stages"]:
        path = run_dir / stage["output"]
        configs.setdefault(stage["kind"], {})[stage["id"]] = stage["config"]
        if stage["kind"] == report_kind:
            continue
        kind = kinds.kind(stage["kind"], run_dir)
        if not path.exists() or not _take(kind.gather, stage, path, rows):
            missing.append(stage["id"])
        elif ROLLOUTS in kind.gather:
            evaluations.append(path)
    notes = [training_note(configs["train"])] if configs.get("train") else []
    if missing:
        notes.append(
            f"{len(missing)} stage(s) have not finished, so their results are absent: "
            + ", ".join(missing[:8])
            + (" …" if len(missing) > 8 else "")
        )
    frames = rows.pop(ROLLOUTS)
    rollouts = pd.concat(frames, ignore_index=True) if frames else empty_rollouts()
    run = {
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
        "provenance": run_provenance(manifest, evaluations),
    }
    return run, rows


def _take(
    gatherers: Mapping[str, Any], stage: Mapping[str, Any], path: Path, rows: dict[str, list]
) -> bool:
    """Add what one finished stage contributes to ``rows`` (the fields it has); False, adding
    nothing, when a gatherer finds its output incomplete."""
    added = []
    for name, gatherer in gatherers.items():
        if name in rows:
            found = gatherer(stage, path)
            if found is None:
                return False
            added.append((name, found))
    for name, found in added:
        rows[name] += found
    return True


def gather(run_dir: str | Path, kinds: StageKinds) -> ReportData:
    """Everything a filtering study's report shows, read from ``run_dir``'s finished artifacts
    by the gatherers of ``kinds``, with the study's per-rollout table the results were computed
    from (``rollouts``: :func:`elicit_jax.pipeline.evidence.cell_frame` rows of every finished
    evaluation)."""
    fields = (*report_rows.ROW_FIELDS, "maps")
    run, rows = gather_fields(run_dir, REPORT_STAGE, kinds, fields)
    results = run.pop("results")
    return ReportData(
        **run,
        results=tuple(r for r in results if r.study == "main"),
        heldout=tuple(r for r in results if r.study != "main"),
        **{name: tuple(found) for name, found in rows.items()},
    )
