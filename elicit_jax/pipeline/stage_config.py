"""Stage configs: each ``resolve_*`` turns a stage's raw overrides into the library's full,
validated config (unknown fields are an error naming the section), so a changed library default
changes the recorded config and re-runs the stage. They are the ``resolve`` of the stage kinds
(:data:`elicit_jax.pipeline.stages.FILTERING_KINDS`); a stage planned in another collection than the
first (``[collections]``) carries ``collection = c`` beside it, and a stage of named sizes
other than the default ``sizes = "<name>"`` (:mod:`elicit_jax.pipeline.sizes`)
(:meth:`~elicit_jax.pipeline.stage_kind.StageKind.config`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.definition import section_fields

PROVISIONAL_PRESET = "square-nut"
"""The preset the contrast-set scores are judged under before the fit (see :func:`resolve_score`);
the same values the pipelines have always recorded in their [score] stage configs."""

FILTER_METHODS = {
    "filtered": ("m", "pair"),
    "filtered-valley": ("m", "pair"),
    "filtered-episode": ("m", "episode"),
    "random": ("random", None),
    "longest": ("longest", None),
    "shortest": ("shortest", None),
    "likelihood": ("likelihood", None),
    "novelty": ("novelty", None),
}


def _split(raw: Mapping[str, Any], meta: tuple[str, ...]) -> tuple[dict, dict]:
    return {k: raw[k] for k in meta if k in raw}, {k: v for k, v in raw.items() if k not in meta}


def resolve_collect(raw: dict[str, Any]) -> dict[str, Any]:
    """A collect stage's config: its role and the collection's config (checks the operator)."""
    from elicit_jax.sim.collect import CollectConfig
    from elicit_jax.sim.operators import operator_names

    meta, over = _split(raw, ("role",))
    known = operator_names(over["task"])
    if over["operator"] not in known:
        raise ElicitError(
            f"task '{over['task']}' has no operator '{over['operator']}' "
            f"(known: {', '.join(known)})"
        )
    cfg = dataclasses.asdict(CollectConfig(**section_fields(CollectConfig, over, "collect")))
    if not cfg["require"]:  # only contrast sets verify traits: other stages keep their hash
        del cfg["require"]
    return {**meta, "collect": cfg}


TRAIN_META = ("task", "profile", "method", "operator", "study", "point")
"""The keys of a train stage's config beside its training config (``profile``: the policy
library's training profile the config starts from)."""


def resolve_train(
    raw: dict[str, Any], section: str = "train", also: tuple[str, ...] = ()
) -> dict[str, Any]:
    """A train stage's config: where it belongs and the profile's full training config.

    Args:
      raw: the stage's :data:`TRAIN_META` and its training options.
      section: the definition's table the options come from, as errors name it (``[train]``;
        the scorer's ``[scorer]``: :func:`elicit_jax.pipeline.spec_parts.parse_scorer`).
      also: the keys that table takes besides the training options (listed as allowed).
    """
    from elicit_jax.policy.config import TrainConfig

    meta, over = _split(raw, TRAIN_META)
    fields = section_fields(TrainConfig, over, section, also)
    cfg = TrainConfig.from_profile(meta["profile"], **fields)
    return {**meta, "train": cfg.to_dict()}


def resolve_score(raw: dict[str, Any]) -> dict[str, Any]:
    """A score stage's config: where it belongs and its scoring config (provisional preset)."""
    from elicit_jax.compat.measures import ScoreConfig, config_dict

    meta, over = _split(raw, ("task", "model", "policy_seed", "set", "checkpoint"))
    meta.setdefault("checkpoint", "best")
    if "thresholds" in over:
        raise ElicitError("[score] takes no thresholds: the pipeline fits them ([thresholds])")
    # The contrast sets are scored before (λ, η) are fitted on them: their M and incompatible
    # column use square-nut's preset, named as provisional in every scores file (the stage
    # reads a fit, when it has one, and judges each D_new under it).
    fields = section_fields(ScoreConfig, over, "score")
    return {**meta, "score": config_dict(ScoreConfig.from_preset(PROVISIONAL_PRESET, **fields))}


def resolve_fit(raw: dict[str, Any]) -> dict[str, Any]:
    """A fit-thresholds stage's config: contrast sets, manual (λ, η) if any, the fit."""
    from elicit_jax.compat.threshold_fit import FitConfig
    from elicit_jax.compat.thresholds import ETA_KEY, LAMBDA_KEY, from_config_fields

    keys = (
        "task",
        "model",
        "compatible_operator",
        "incompatible_operator",
        "holdout_seed",
        "incompatible_seed",
        LAMBDA_KEY,
        ETA_KEY,
        "force",
    )
    meta, over = _split(raw, keys)
    try:  # manual thresholds: both or neither, numbers, finite and > 0
        from_config_fields(dict(meta), "[thresholds]")
    except ElicitError as e:
        raise ElicitError(
            f"[thresholds] {e}: both lambda and eta (manual), or neither (fit)"
        ) from None
    if meta["compatible_operator"] == meta["incompatible_operator"]:
        raise ElicitError("incompatible_operator must differ from the base operator")
    fit = FitConfig(**section_fields(FitConfig, over, "thresholds"))
    return {**meta, "fit": dataclasses.asdict(fit)}


def resolve_filter(raw: dict[str, Any]) -> dict[str, Any]:
    """A filter stage's config: the method, and the filter config it runs with."""
    from elicit_jax.compat.filtering import FilterConfig

    meta, over = _split(raw, ("task", "model", "method", "operator"))
    method, level = FILTER_METHODS[meta["method"]]
    over = {**over, "method": method, **({"level": level} if level else {})}
    if {"thresholds", "lambda_", "lambda", "eta"} & set(over):
        raise ElicitError("[filter] takes its thresholds from the fit stage; set [thresholds]")
    cfg = FilterConfig(**section_fields(FilterConfig, over, "filter"))
    return {**meta, "filter": cfg.to_dict()}


def resolve_evaluate(raw: dict[str, Any]) -> dict[str, Any]:
    """An evaluate stage's config: where it belongs, its checkpoint selection, the evaluation."""
    from elicit_jax.pipeline.evidence import selection_meta
    from elicit_jax.sim.evaluate import EvalConfig

    keys = ("model", "profile", "method", "operator", "seeds", "study", "point")
    meta, over = _split(raw, (*keys, "selection", "select_seed"))
    over = {"checkpoints": ["all"], "select": "best", **over}
    over["checkpoints"] = tuple(str(c) for c in over["checkpoints"])
    cfg = EvalConfig(**section_fields(EvalConfig, over, "evaluate"))
    return {**meta, **selection_meta(meta, cfg.seed), "evaluate": dataclasses.asdict(cfg)}


def resolve_deminf(raw: dict[str, Any]) -> dict[str, Any]:
    """A DemInf stage's config."""
    from elicit_jax.curation.deminf import DemInfConfig

    meta, over = _split(raw, ("task", "operator"))
    return {
        **meta,
        "deminf": dataclasses.asdict(DemInfConfig(**section_fields(DemInfConfig, over, "deminf"))),
    }


def resolve_demo_score(raw: dict[str, Any]) -> dict[str, Any]:
    """A Demo-SCORE stage's config (its task from the config's own)."""
    from elicit_jax.curation.demo_score import DemoScoreConfig

    meta, over = _split(raw, ("model", "operator"))
    cfg = DemoScoreConfig(**section_fields(DemoScoreConfig, over, "demo_score"))
    return {**meta, "task": cfg.task, "demo_score": dataclasses.asdict(cfg)}


def resolve_curate(raw: dict[str, Any]) -> dict[str, Any]:
    """Level and accept fraction of the M-filter budget (from [filter]) and DemInf's own cut
    (from [deminf]); ``rate`` is ``m`` for the ``*-matched`` methods."""
    from elicit_jax.compat.filtering import FilterConfig
    from elicit_jax.curation.deminf import DemInfConfig

    meta, _ = _split(raw, ("task", "model", "method", "operator"))
    filt = FilterConfig(**section_fields(FilterConfig, raw.get("filter", {}), "filter"))
    deminf = DemInfConfig(**section_fields(DemInfConfig, raw.get("deminf", {}), "deminf"))
    return {
        **meta,
        "rate": "m" if meta["method"].endswith("-matched") else "own",
        "level": filt.level,
        "accept_fraction": filt.accept_fraction,
        "drop_fraction": deminf.drop_fraction,
    }
