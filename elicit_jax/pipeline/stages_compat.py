"""The compatibility stages: score demonstrations with the base policy, fit (λ, η) on the
contrast sets, filter each D_new, draw the maps, and the λ variants (the sensitivity study's
points, the new-data valley rule).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Any

from elicit_jax.artifact import atomic_path, make_header, write_json
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.runner import StageContext
from elicit_jax.pipeline.stages_policy import DEMOS_FILE, SCORES_FILE

if TYPE_CHECKING:
    from elicit_jax.compat.thresholds import Thresholds


def score_stage(ctx: StageContext) -> None:
    """Score the ``demos*`` inputs (concatenated) with the base policy of ``policy_seed``;
    with a ``thresholds`` input (each D_new, scored after the fit), its pairs are judged under
    the fitted (λ, η), otherwise (the contrast sets the fit needs) under the [score] settings'."""
    from elicit_jax.compat.score_file import score_file
    from elicit_jax.compat.show import scoring_bar
    from elicit_jax.data.demos import concat_demos, read_demos, write_demos
    from elicit_jax.policy.loaded import load_policy

    cfg = ctx.config
    which = cfg["checkpoint"]
    policy = load_policy(ctx.inputs["policy"], which, seed=cfg["policy_seed"]).policy
    config = _score_config(ctx, cfg["score"])
    names = sorted(n for n in ctx.inputs if n.startswith("demos"))
    with atomic_path(ctx.output) as tmp:
        tmp.mkdir()
        demos = ctx.inputs[names[0]]
        if len(names) > 1:
            demos = tmp / DEMOS_FILE
            parts = [read_demos(ctx.inputs[n]) for n in names]
            write_demos(demos, concat_demos(parts), inputs={n: ctx.inputs[n] for n in names})
        result = score_file(
            policy,
            demos,
            tmp / SCORES_FILE,
            config,
            policy_path=ctx.inputs["policy"],
            policy_info={"which": which, "seed": cfg["policy_seed"]},
            progress=scoring_bar,
        )
        header = make_header(
            "pipeline-scores",
            1,
            config=dict(cfg),
            inputs=dict(ctx.inputs),
            files=[SCORES_FILE, result.episodes_path.name],
            n_pairs=result.n_pairs,
        )
        write_json(tmp / "artifact.json", header)


def _score_config(ctx: StageContext, stored: dict[str, Any]) -> Any:
    """The scoring config of the stage: with the fitted thresholds when the stage reads a
    fit, else the [score] settings' (provisional), each saying where they came from."""
    from elicit_jax.compat.measures import config_from_dict
    from elicit_jax.compat.thresholds import read_thresholds

    if "thresholds" not in ctx.inputs:
        return config_from_dict(
            stored,
            "provisional: the [score] settings' λ and η; the pipeline fits (λ, η) on these "
            "contrast-set scores, and its filters and maps use the fitted values",
        )
    fitted = read_thresholds(ctx.inputs["thresholds"])
    source = f"the pipeline's threshold fit ({ctx.inputs['thresholds']})"
    config = config_from_dict(stored, source)
    return dataclasses.replace(config, thresholds=dataclasses.replace(fitted, source=source))


def fit_stage(ctx: StageContext) -> None:
    """Fit (λ, η) on the contrast scores (or record manual thresholds) with a fit report; its
    training-data checks name the policy that scored: the base policy, or the cell's scorer."""
    from elicit_jax.compat.fit import FitJob, fit_scores_file
    from elicit_jax.compat.show import print_report
    from elicit_jax.compat.threshold_fit import FitConfig
    from elicit_jax.compat.thresholds import from_config_fields

    cfg = ctx.config
    job = FitJob(
        compatible=f"operator:{cfg['compatible_operator']}",
        incompatible=f"operator:{cfg['incompatible_operator']}",
        fit=FitConfig(**cfg["fit"]),
        manual=from_config_fields(dict(cfg), "the pipeline's [thresholds] (manual)"),
        force=bool(cfg.get("force", False)),
        scorer=scored_by_scorer(ctx.inputs["scores"]),
    )
    scores = ctx.inputs["scores"] / SCORES_FILE
    fit_scores_file(scores, ctx.output, job, show=lambda header: print_report(header, ctx.console))


def scored_by_scorer(scores_dir: Path) -> bool:
    """Whether a score stage's output was scored by the cell's own scorer (``[scorer]``,
    whose train stage writes ``policies/<task>/<model>/scorer``), not the base policy: the
    policy input its header records."""
    from elicit_jax.artifact import read_header
    from elicit_jax.pipeline.gather import SCORER_METHOD

    policy = (read_header(scores_dir).get("inputs") or {}).get("policy") or {}
    return Path(policy.get("path", "")).name == SCORER_METHOD


def filter_stage(ctx: StageContext) -> None:
    """Filter one D_new by its scores under the fitted thresholds (M-filter or a baseline).

    When the filter drops every pair (e.g. every demo of a conflicting operator rejected), the
    output holds no demonstrations file and the retraining uses D_base alone.
    """
    import numpy as np

    from elicit_jax.compat.filtering import FilterConfig, drop_mask
    from elicit_jax.compat.score_file import read_scores
    from elicit_jax.compat.thresholds import read_thresholds

    cfg = FilterConfig.from_dict(ctx.config["filter"], read_thresholds(ctx.inputs["thresholds"]))
    scores_path = ctx.inputs["scores"] / SCORES_FILE
    _, scores = read_scores(scores_path)
    drop, reason = drop_mask(scores, cfg)
    counts = {
        "pairs_in": int(drop.size),
        "pairs_dropped": int(drop.sum()),
        "episodes_in": int(np.unique(scores["episode"]).size),
        "episodes_out": 0,
    }
    with atomic_path(ctx.output) as tmp:
        tmp.mkdir()
        write_filter_output(ctx, tmp, scores_path, ctx.inputs["demos"], cfg, drop, reason, counts)


def write_filter_output(
    ctx: StageContext,
    tmp: Path,
    scores_path: Path,
    source: Path,
    cfg: Any,
    drop: Any,
    reason: str,
    counts: dict[str, int],
    keep: tuple[str, ...] = (),
) -> None:
    """Write a filter-like stage's output into ``tmp``: the kept demonstrations (none when
    every pair is dropped: the retraining then uses D_base alone) and its header.

    Args:
      ctx: the stage.
      tmp: the output directory being written.
      scores_path: the scores the filter reads.
      source: the demonstrations filtered.
      cfg: the filter config (with the fitted λ, η).
      drop: ``(n_pairs,)`` the pairs dropped; None when there was nothing to filter.
      reason: what the filter did, in words.
      counts: pairs/episodes in and dropped; ``episodes_out`` is set here.
      keep: other files of ``tmp`` the header lists (after the demonstrations).
    """
    from elicit_jax.compat.filtering import filter_demos

    files: list[str] = []
    if drop is not None and not drop.all():
        result = filter_demos(scores_path, source, tmp / DEMOS_FILE, cfg)
        counts["episodes_out"] = result.episodes_out
        files = [DEMOS_FILE, *keep, result.log_path.name]
    elif drop is not None:
        reason += "; every pair dropped, so the retraining uses D_base alone"
    write_filter_header(ctx, tmp, cfg.thresholds, reason, files, counts)


def write_filter_header(
    ctx: StageContext,
    tmp: Path,
    thresholds: Thresholds,
    reason: str,
    files: list[str],
    counts: dict[str, int],
    **extra: Any,
) -> None:
    """The header of every filter-like stage's output (M-filter, baselines, curation cuts,
    a session's M-filter): what it kept of its input and why.

    Args:
      ctx: the stage.
      tmp: the output directory being written.
      thresholds: the (λ, η) it ran under.
      reason: what the filter did, in words.
      files: the files of ``tmp`` it wrote (none: the retraining uses D_base alone).
      counts: ``pairs_in``, ``pairs_dropped``, ``episodes_in``, ``episodes_out``.
      **extra: other header fields (a curation cut: whether its scores are trusted).
    """
    header = make_header(
        "pipeline-filter",
        1,
        config=dict(ctx.config),
        inputs=dict(ctx.inputs),
        thresholds=thresholds.to_json(),
        reason=reason,
        files=files,
        **extra,
        **counts,
    )
    write_json(tmp / "artifact.json", header)


def map_stage(ctx: StageContext) -> None:
    """Draw the compatibility map: held-out base demos and each D_new, one panel each."""
    import numpy as np

    from elicit_jax.compat.maps import write_png
    from elicit_jax.compat.score_file import read_scores
    from elicit_jax.compat.thresholds import read_thresholds

    thresholds = read_thresholds(ctx.inputs["thresholds"])
    cols = ("likelihood", "novelty", "operator", "incompatible")
    _, ref = read_scores(ctx.inputs["scores:contrast"] / SCORES_FILE, cols)
    keep = np.asarray(ref["operator"]).astype(str) == ctx.config["base_operator"]
    parts = [{k: np.asarray(v)[keep] for k, v in ref.items()}]
    parts[0]["operator"] = np.full(int(keep.sum()), f"{ctx.config['base_operator']} (held-out)")
    for op in ctx.config["operators"]:
        parts.append(read_scores(ctx.inputs[f"scores:{op}"] / SCORES_FILE, cols)[1])
    scores = {k: np.concatenate([np.asarray(p[k]) for p in parts]) for k in cols}
    write_png(scores, thresholds, ctx.output, axis=ctx.config.get("axis", "likelihood-error"))


def _fitted_margin(ctx: StageContext, refusal: str) -> tuple[Thresholds, tuple[float, float]]:
    """The fitted thresholds of the stage's ``thresholds`` input and the λ range of the fit's
    margin; thresholds set by hand, or without a margin, are refused with ``refusal``."""
    from elicit_jax.compat.thresholds import read_thresholds, read_thresholds_header

    fit = read_thresholds_header(ctx.inputs["thresholds"])
    lo, hi = fit.get("report", {}).get("lambda_range", (None, None))
    if fit.get("method", "fit") != "fit" or lo is None:
        raise ElicitError(refusal, ctx.inputs["thresholds"])
    return read_thresholds(ctx.inputs["thresholds"]), (lo, hi)


def lambda_point_stage(ctx: StageContext) -> None:
    """Thresholds with λ at point k of ``points`` evenly spaced over the fit's margin range
    (η as fitted), for the sensitivity study."""
    from elicit_jax.compat.thresholds import write_thresholds

    fitted, (lo, hi) = _fitted_margin(
        ctx, "the λ-sensitivity study needs fitted thresholds with a margin, not manual ones"
    )
    k, n = int(ctx.config["point"]), int(ctx.config["points"])
    point = float(lo + (hi - lo) * k / (n - 1))
    write_thresholds(
        ctx.output,
        dataclasses.replace(fitted, lam=point, source=f"sensitivity point {k} of {n}"),
        config=dict(ctx.config),
        inputs={"fit": ctx.inputs["thresholds"]},
        method="sensitivity-point",
        report={"point": k, "points": n, "lambda_range": [lo, hi], "fitted_lambda": fitted.lam},
    )


def lambda_valley_stage(ctx: StageContext) -> None:
    """Thresholds with λ moved, inside the fit's margin, to the sparsest point of the familiar
    pairs of every D_new (:mod:`elicit_jax.compat.valley`); η as fitted."""
    import numpy as np

    from elicit_jax.compat.score_file import read_scores
    from elicit_jax.compat.thresholds import write_thresholds
    from elicit_jax.compat.valley import valley_lambda

    fitted, (lo, hi) = _fitted_margin(
        ctx, "the valley rule moves a fitted λ inside its margin; these thresholds were not fitted"
    )
    cols = ("likelihood", "novelty")
    parts = [
        read_scores(p / SCORES_FILE, cols)[1] for n, p in ctx.inputs.items() if n != "thresholds"
    ]
    ell = np.concatenate([p["likelihood"] for p in parts])
    nu = np.concatenate([p["novelty"] for p in parts])
    new_lam, report = valley_lambda(ell, nu, fitted, lo, hi)
    write_thresholds(
        ctx.output,
        dataclasses.replace(fitted, lam=new_lam, source="the new-data valley rule"),
        config=dict(ctx.config),
        inputs=dict(ctx.inputs),
        method="new-data-valley",
        report=report,
    )
