"""``fit-thresholds`` end to end: select contrast sets in a scores file, fit (or take given)
thresholds, report how well they separate the sets, write a ``thresholds`` artifact.

Example:
    >>> fit_scores_file("scores.parquet", "operator:base", "operator:op4", "thresholds.json")

The objective is explained in :mod:`elicit_jax.compat.thresholds` and ``docs/thresholds.md``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.compat.measures import is_incompatible
from elicit_jax.compat.selection import parse_selection, select_episodes
from elicit_jax.compat.threshold_fit import (
    FitConfig,
    evaluate_thresholds,
    fit_thresholds,
    operator_rejections,
)
from elicit_jax.compat.thresholds import Thresholds, fitted_on, write_thresholds
from elicit_jax.compat.trust import (
    Verdict,
    assess_fit,
    held_out_in_sample,
    one_operator,
    operator_decisions,
    training_overlap,
    training_rejections,
)
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.compat.training_data import TrainingEvidence

#: ``show(header)`` shows a fit report (:func:`elicit_jax.compat.show.print_report`).
Show = Callable[[dict[str, Any]], None]


@dataclasses.dataclass(frozen=True)
class FitJob:
    """A ``fit-thresholds`` run.

    Attributes:
      compatible: selection text of the compatible set (``operator:…``, ``episodes:…``,
        ``label:col=value``); optional with manual thresholds.
      incompatible: selection text of the incompatible set.
      fit: fitting settings.
      manual: hand-set thresholds: skip fitting, only evaluate (if sets are given) and
        record them.
      force: write a fit judged meaningless (:mod:`elicit_jax.compat.trust`) anyway, marked
        untrustworthy, instead of refusing.
      base: the base policy's training demonstrations (``--base``), to check the thresholds
        against; default: those the scores file holds and the files the checkpoint records
        (:mod:`elicit_jax.compat.training_data`).
      scorer: the scores were computed by a policy of their own trained on D_base (a
        pipeline's ``[scorer]``), not the base policy: the training-data checks' messages
        name that policy's training demos.
    """

    compatible: str | None = None
    incompatible: str | None = None
    fit: FitConfig = dataclasses.field(default_factory=FitConfig)
    manual: Thresholds | None = None
    force: bool = False
    base: tuple[str, ...] = ()
    scorer: bool = False

    def __post_init__(self) -> None:
        if (self.compatible is None) != (self.incompatible is None):
            raise ElicitError("give both --compatible and --incompatible, or neither")
        if self.compatible is None and self.manual is None:
            raise ElicitError(
                "fitting needs contrast sets: give --compatible and --incompatible (or --lambda "
                "and --eta to record hand-set thresholds)"
            )


def contrast_labels(
    columns: dict[str, np.ndarray], compatible: str, incompatible: str
) -> dict[int, bool]:
    """Episode id -> True/False from two selections; errors when they overlap."""
    comp = select_episodes(parse_selection(compatible), columns)
    inc = select_episodes(parse_selection(incompatible), columns)
    both = sorted(set(comp.tolist()) & set(inc.tolist()))
    if both:
        raise ElicitError(
            f"episode(s) {both[:5]} are in both the compatible and the incompatible set"
        )
    return {**{int(e): True for e in comp}, **{int(e): False for e in inc}}


def _fit_report(s: dict[str, np.ndarray], labels: dict[int, bool], job: FitJob) -> dict:
    """λ, η, method and the contrast part of the report (fit, or manual thresholds)."""
    ell, nu, ep = s["likelihood"], s["novelty"], s["episode"]
    f = job.fit.accept_fraction
    if job.manual is None:
        fit = fit_thresholds(ell, nu, ep, labels, job.fit)
        chosen, method = fit.thresholds, "fit"
        ba, decisions = fit.balanced_accuracy, fit.episodes
        extra = {
            "margin_steps": fit.margin_steps,
            "margin_quantile": fit.margin_quantile,
            "lambda_range": list(fit.lambda_range),
            "eta_range": list(fit.eta_range),
            "loo_accuracy": fit.loo_accuracy,
            "n_loo": fit.n_loo,
        }
    else:
        chosen, method = job.manual, "manual"
        if not labels:
            return {"thresholds": chosen, "method": method, "report": {}}
        ba, decisions = evaluate_thresholds(ell, nu, ep, labels, chosen, f)
        extra = {}
    names = s.get("source_episode")
    first = {int(e): i for i, e in reversed(list(enumerate(ep)))} if names is not None else {}
    contrast = []
    for e, c, fr, r in zip(
        decisions["episode"],
        decisions["compatible"],
        decisions["fraction_incompatible"],
        decisions["rejected"],
        strict=True,
    ):
        row = {
            "episode": int(e),
            "compatible": bool(c),
            "fraction_incompatible": float(fr),
            "rejected": bool(r),
        }
        if names is not None:
            row["source_episode"] = str(names[first[int(e)]])
        contrast.append(row)
    if method == "fit":
        extra["in_sample_accuracy"] = held_out_in_sample(contrast)
    report = {
        "balanced_accuracy": ba,
        **extra,
        "n_compatible": int(np.sum(decisions["compatible"])),
        "n_incompatible": int(np.sum(~decisions["compatible"])),
        "contrast": contrast,
    }
    return {"thresholds": chosen, "method": method, "report": report}


def _rejected_episodes(s: dict[str, np.ndarray], out: dict[str, Any], f: float) -> np.ndarray:
    ell, nu, ep = s["likelihood"], s["novelty"], s["episode"]
    inc = is_incompatible(ell, nu, *out["thresholds"].pair)
    ids, index = np.unique(ep, return_inverse=True)
    n_inc = np.bincount(index, weights=inc, minlength=len(ids))
    return ids[n_inc > f * np.bincount(index, minlength=len(ids))]


def _contrast_verdict(
    s: dict[str, np.ndarray], labels: dict[int, bool], out: dict[str, Any], f: float
) -> Verdict:
    """The contrast checks of :mod:`elicit_jax.compat.trust` (sets given only)."""
    if not labels:
        return Verdict(unchecked=("contrast sets: none given, so no accuracy or margin",))
    ep, ops = s["episode"], np.asarray(s["operator"]).astype(str)
    comp = [e for e, c in labels.items() if c]
    bad = [e for e, c in labels.items() if not c]
    comp_ops = set(ops[np.isin(ep, comp)].tolist())
    rejected = _rejected_episodes(s, out, f)
    return assess_fit(
        out["report"],
        compatible_operators=comp_ops,
        operator_decisions=operator_decisions(ep, ops, rejected.tolist(), bad),
        pairs_per_set=(int(np.isin(ep, comp).sum()), int(np.isin(ep, bad).sum())),
    ) + one_operator(comp_ops, set(ops[np.isin(ep, bad)].tolist()))


def _training_verdict(
    ev: TrainingEvidence, labels: dict[int, bool], out: dict[str, Any], job: FitJob
) -> tuple[Verdict, dict[str, Any]]:
    """Checks (a) and (c) against the scoring policy's training demos, and their report."""
    rejected = ev.rejected(out["thresholds"], job.fit.accept_fraction)
    verdict = Verdict(unchecked=ev.notes) + training_rejections(
        rejected, ev.n_demos, ev.source, scorer=job.scorer
    )
    if labels and ev.training is not None and ev.scored is not None:
        sets = {
            "compatible": [e for e, c in labels.items() if c],
            "incompatible": [e for e, c in labels.items() if not c],
        }
        verdict += training_overlap(sets, ev.scored, ev.training, scorer=job.scorer)
    check = {"demos": ev.n_demos, "rejected": rejected, "source": ev.source}
    return verdict, check


def fit_scores_file(
    scores_path: str | Path, out_path: str | Path, job: FitJob, *, show: Show | None = None
) -> dict[str, Any]:
    """Fit or evaluate thresholds on a scores file and write ``thresholds.json``.

    The fit's trustworthiness is assessed (:mod:`elicit_jax.compat.trust`), recorded under
    ``report.trust`` and shown; a meaningless fit is refused unless ``job.force``.

    Args:
      scores_path: a ``scores`` artifact.
      out_path: the ``thresholds`` artifact to write.
      job: the contrast sets and settings.
      show: called with the header (``lambda``, ``eta``, ``method``, ``report``) to show the
        report, also when a meaningless fit is refused (the CLI passes
        :func:`~elicit_jax.compat.show.print_report`).

    Returns:
      The written header (``lambda``, ``eta``, ``report``, ...).

    Raises:
      ElicitError: bad sets, a failed fit, or a meaningless fit without ``force``.
    """
    from elicit_jax.artifact import refuse_overwriting_inputs
    from elicit_jax.compat.score_file import read_scores
    from elicit_jax.compat.training_data import gather

    refuse_overwriting_inputs([out_path], [scores_path, *job.base])
    cols = [c for c in _needed(job) if c not in ("episode", "operator", "likelihood", "novelty")]
    scores_header, s = read_scores(
        scores_path,
        columns=["episode", "operator", "likelihood", "novelty", *cols],
        optional=["source_episode"],
    )
    try:
        labels = (
            contrast_labels(s, job.compatible, job.incompatible)
            if job.compatible is not None and job.incompatible is not None
            else {}
        )
    except ElicitError as e:  # a selection's error names the scores file it was made in
        raise (e if e.path else ElicitError(str(e), scores_path)) from e
    f = job.fit.accept_fraction
    evidence = gather(scores_path, scores_header, s, job.base)
    out = _fit_report(s, labels, job)
    report = out["report"]
    verdict, report["training_check"] = _training_verdict(evidence, labels, out, job)
    verdict = _contrast_verdict(s, labels, out, f) + verdict
    verdict = dataclasses.replace(verdict, forced=job.force and verdict.meaningless)
    report["trust"] = verdict.to_dict()
    report["per_operator"] = operator_rejections(
        s["likelihood"], s["novelty"], s["episode"], s["operator"], out["thresholds"], f
    )
    config = {
        "compatible": job.compatible,
        "incompatible": job.incompatible,
        "force": job.force,
        "base": list(job.base),
        **dataclasses.asdict(job.fit),
    }
    header = {**out["thresholds"].to_json(), "method": out["method"]}
    if verdict.meaningless and out["method"] == "fit" and not job.force:
        if show is not None:
            show({**header, "report": report})
        raise ElicitError(
            "the threshold fit is meaningless (" + "; ".join(verdict.severe) + "); nothing "
            "written — use other contrast sets, or pass --force to write it marked untrustworthy",
            scores_path,
        )
    header = write_thresholds(
        out_path,
        fitted_on(out["thresholds"], scores_header),
        method=out["method"],
        inputs={"scores": scores_path},
        config=config,
        report=report,
    )
    if show is not None:
        show(header)
    return header


def _needed(job: FitJob) -> list[str]:
    out = []
    for text in (job.compatible, job.incompatible):
        if text is None:
            continue
        sel = parse_selection(text)
        if sel.kind == "label":
            out.append(sel.values[0])
    return out
