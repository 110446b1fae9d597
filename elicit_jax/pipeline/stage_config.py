"""Stage configs: :func:`resolve_config` turns a stage's raw overrides into the library's full,
validated config (unknown fields are an error naming the section), so a changed library default
changes the recorded config and re-runs the stage.

A stage planned in another collection than the first (``[collections]``) carries
``collection = c`` beside its library config.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.curation_stages import resolve_cupid, resolve_quality
from elicit_jax.pipeline.definition import section_fields

PROVISIONAL_PRESET = "square-nut"
"""The preset the contrast-set scores are judged under before the fit (see ``_resolve_score``);
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


def _resolve_collect(raw: dict[str, Any]) -> dict[str, Any]:
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


def _resolve_train(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.policy.config import TrainConfig

    meta, over = _split(raw, ("task", "profile", "method", "operator", "study", "point"))
    cfg = TrainConfig.from_profile(meta["profile"], **section_fields(TrainConfig, over, "train"))
    return {**meta, "train": cfg.to_dict()}


def _resolve_score(raw: dict[str, Any]) -> dict[str, Any]:
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


def _resolve_fit(raw: dict[str, Any]) -> dict[str, Any]:
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


def _resolve_filter(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.compat.filtering import FilterConfig

    meta, over = _split(raw, ("task", "model", "method", "operator"))
    method, level = FILTER_METHODS[meta["method"]]
    over = {**over, "method": method, **({"level": level} if level else {})}
    if {"thresholds", "lambda_", "lambda", "eta"} & set(over):
        raise ElicitError("[filter] takes its thresholds from the fit stage; set [thresholds]")
    cfg = FilterConfig(**section_fields(FilterConfig, over, "filter"))
    return {**meta, "filter": cfg.to_dict()}


def _resolve_evaluate(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.pipeline.evidence import selection_meta
    from elicit_jax.sim.evaluate import EvalConfig

    keys = ("model", "profile", "method", "operator", "seeds", "study", "point")
    meta, over = _split(raw, (*keys, "selection", "select_seed"))
    over = {"checkpoints": ["all"], "select": "best", **over}
    over["checkpoints"] = tuple(str(c) for c in over["checkpoints"])
    cfg = EvalConfig(**section_fields(EvalConfig, over, "evaluate"))
    return {**meta, **selection_meta(meta, cfg.seed), "evaluate": dataclasses.asdict(cfg)}


def _resolve_deminf(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.curation.deminf import DemInfConfig

    meta, over = _split(raw, ("task", "operator"))
    return {
        **meta,
        "deminf": dataclasses.asdict(DemInfConfig(**section_fields(DemInfConfig, over, "deminf"))),
    }


def _resolve_demo_score(raw: dict[str, Any]) -> dict[str, Any]:
    from elicit_jax.curation.demo_score import DemoScoreConfig

    meta, over = _split(raw, ("model", "operator"))
    cfg = DemoScoreConfig(**section_fields(DemoScoreConfig, over, "demo_score"))
    return {**meta, "task": cfg.task, "demo_score": dataclasses.asdict(cfg)}


def _resolve_curate(raw: dict[str, Any]) -> dict[str, Any]:
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


_RESOLVERS = {
    "collect": _resolve_collect,
    "train": _resolve_train,
    "score": _resolve_score,
    "fit-thresholds": _resolve_fit,
    "filter": _resolve_filter,
    "evaluate": _resolve_evaluate,
    "deminf": _resolve_deminf,
    "demo-score": _resolve_demo_score,
    "curate": _resolve_curate,
    "cupid": resolve_cupid,
    "quality": resolve_quality,
}


def resolve_config(kind: str, raw: dict[str, Any]) -> dict[str, Any]:
    """Full, validated config of a stage: pipeline keys plus the library config's fields
    (``map`` and ``report`` stages keep their raw config); a ``collection`` key (a stage of
    a later collection) and a ``sizes`` key (a stage of named sizes other than the default:
    :mod:`elicit_jax.pipeline.sizes`) are kept beside them."""
    resolver = _RESOLVERS.get(kind)
    if resolver is None:
        return raw
    kept = [k for k in ("collection", "sizes") if k in raw]
    if not kept:
        return resolver(raw)
    rest = {k: v for k, v in raw.items() if k not in kept}
    out = resolver(rest)
    if "collection" in raw:
        out["collection"] = int(raw["collection"])
    if "sizes" in raw:
        out["sizes"] = str(raw["sizes"])
    return out
