"""Curate D_new with DemInf, Demo-SCORE, CUPID or the quality flags: score its demonstrations,
drop the lowest, write the kept ones (``elicit-jax filter --method deminf|demo-score|cupid|
quality``).

:func:`curation_scores` computes one score per demonstration with the chosen method;
:func:`curate_demos` cuts them by the method's own rule or by the M-filter's budget
(:func:`matched_rule`) and writes the result like the M-filter does: a ``demos`` artifact
(D_base first when given, the ``subset`` column saying ``base``/``new``, and the original ids in
``pre_filter_episode`` / ``pre_filter_step``) and a sibling ``<out>.dropped.parquet`` log of the
dropped pairs with their demonstration's score and the reason.

Example:
    >>> scores = curation_scores(CurateConfig(method="deminf"), "new.parquet", "base.parquet")
    >>> curate_demos(scores, "new.parquet", "kept.parquet", OwnRule(0.2), "base.parquet")
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import numpy as np

from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.curation.cupid import CupidConfig
from elicit_jax.curation.deminf import DemInfConfig, deminf_scores
from elicit_jax.curation.demo_score import DemoScoreConfig, demo_score_scores
from elicit_jax.curation.episodes import (
    EpisodeScores,
    MatchedRule,
    OwnRule,
    select_drop,
    write_episode_scores,
)
from elicit_jax.curation.quality import QualityConfig
from elicit_jax.errors import ElicitError

METHODS = ("deminf", "demo-score", "cupid", "quality")


@dataclasses.dataclass(frozen=True)
class CurateConfig:
    """Which curation method and its settings.

    Attributes:
      method: ``deminf``, ``demo-score``, ``cupid`` or ``quality``.
      deminf: DemInf estimator settings.
      demo_score: Demo-SCORE rollout and classifier settings.
      cupid: CUPID influence estimator settings.
      quality: per-episode quality metrics and their outlier rule.
    """

    method: str = "deminf"
    deminf: DemInfConfig = dataclasses.field(default_factory=DemInfConfig)
    demo_score: DemoScoreConfig = dataclasses.field(default_factory=DemoScoreConfig)
    cupid: CupidConfig = dataclasses.field(default_factory=CupidConfig)
    quality: QualityConfig = dataclasses.field(default_factory=QualityConfig)

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ElicitError(f"unknown curation method '{self.method}' ({', '.join(METHODS)})")


def method_config(config: CurateConfig) -> dict[str, Any]:
    """The settings of the chosen method only, for artifact headers."""
    key = config.method.replace("-", "_")
    return {key: dataclasses.asdict(getattr(config, key))}


def curation_scores(
    config: CurateConfig,
    demos_path: str | Path,
    base_path: str | Path | None = None,
    policy_path: str | Path | None = None,
    progress: Callable[[int, float], None] | None = None,
    trajectories_path: str | Path | None = None,
) -> EpisodeScores:
    """One score per demonstration of ``demos_path`` (higher = keep).

    Args:
      config: method and settings.
      demos_path: D_new.
      base_path: D_base; DemInf estimates over D_base ∪ D_new, CUPID's training set is it.
      policy_path: Demo-SCORE: the training run to roll out (trained on the data to curate);
        CUPID: the training run whose rollouts ``trajectories_path`` holds.
      progress: Demo-SCORE: called with ``(epoch, success rate)`` per rolled-out checkpoint.
      trajectories_path: CUPID: ``evaluate --trajectories`` of that policy.
    """
    from elicit_jax.data.demos import read_demos

    new = read_demos(demos_path)
    base = None if base_path is None else read_demos(base_path)
    if config.method == "deminf":
        return deminf_scores(new, base, config.deminf)
    if config.method == "quality":
        from elicit_jax.curation.quality import quality_episode_scores

        return quality_episode_scores(new, config.quality)
    if config.method == "cupid":
        from elicit_jax.curation.cupid import cupid_file_scores

        if policy_path is None or trajectories_path is None:
            raise ElicitError(
                "cupid needs the policy (--policy) and its recorded rollouts (--trajectories, "
                "from elicit-jax evaluate --trajectories --action-noise)"
            )
        return cupid_file_scores(policy_path, trajectories_path, new, base, config.cupid)
    if policy_path is None:
        raise ElicitError("demo-score rolls out a policy: give --policy (a training run)")
    return demo_score_scores(policy_path, new, config.demo_score, progress)


def matched_rule(
    scores_path: str | Path,
    level: Literal["pair", "episode"],
    thresholds: Thresholds | None = None,
    accept_fraction: float = 0.05,
) -> MatchedRule:
    """The M-filter's budget on a scores file: its incompatible pairs (pair level) or its
    rejected demonstrations (episode level), under ``thresholds`` or the scores' own column."""
    from elicit_jax.compat.filtering import FilterConfig, drop_mask
    from elicit_jax.compat.score_file import read_scores

    _, scores = read_scores(scores_path)
    cfg = FilterConfig(
        level=level, method="m", thresholds=thresholds, accept_fraction=accept_fraction
    )
    drop, _ = drop_mask(scores, cfg)
    if level == "pair":
        return MatchedRule(pairs=int(drop.sum()))
    return MatchedRule(episodes=int(np.unique(np.asarray(scores["episode"])[drop]).size))


@dataclasses.dataclass(frozen=True)
class CurateResult:
    """Counts of a curation run (as :class:`~elicit_jax.compat.filtering.FilterResult`)."""

    out_path: Path | None
    log_path: Path | None
    pairs_in: int
    pairs_dropped: int
    episodes_in: int
    episodes_out: int
    reason: str
    duplicates: dict[int, int] = dataclasses.field(default_factory=dict)
    """Episodes of D_new dropped as identical to D_base's: new id -> base id."""


def _base_and_duplicates(demos: Any, base_path: str | Path | None) -> tuple[Any, dict[int, int]]:
    """D_base (or None) and the episodes of ``demos`` identical to one of its episodes."""
    from elicit_jax.data.demos import read_demos
    from elicit_jax.data.duplicates import duplicates_of

    if base_path is None:
        return None, {}
    base = read_demos(base_path)
    return base, duplicates_of(demos, base)


def curate_demos(
    scores: EpisodeScores,
    demos_path: str | Path,
    out_path: str | Path,
    rule: OwnRule | MatchedRule,
    base_path: str | Path | None = None,
    *,
    config: dict[str, Any] | None = None,
    inputs: dict[str, str | Path] | None = None,
    allow_empty: bool = False,
) -> CurateResult:
    """Drop the demonstrations ``rule`` picks from ``demos_path`` and write the rest.

    Args:
      scores: per-demonstration scores of ``demos_path``.
      demos_path: D_new.
      out_path: the curated ``demos`` artifact.
      rule: the method's own cut or a matched budget.
      base_path: D_base, kept whole and placed first.
      config: recorded in the output header.
      inputs: extra inputs recorded (with hashes) in the header.
      allow_empty: when every demonstration is dropped and there is no D_base, write nothing
        (and say so) instead of failing.
    """
    import pyarrow as pa

    from elicit_jax.artifact import atomic_paths, make_header, write_parquet
    from elicit_jax.compat.filtering import PRE_EPISODE, PRE_STEP, apply_drop, log_path
    from elicit_jax.data.demos import concat_demos, read_demos, write_demos
    from elicit_jax.data.duplicates import duplicate_reasons

    demos = read_demos(demos_path)
    ids = np.asarray(scores.episode)
    if not np.array_equal(ids, demos.episode_ids):
        raise ElicitError("these demonstration scores were computed on another file", demos_path)
    drop_ep, reason = select_drop(scores, rule)
    base, dups = _base_and_duplicates(demos, base_path)
    drop_ep = drop_ep | np.isin(ids, list(dups))
    index = np.repeat(np.arange(len(ids)), np.asarray(scores.length))
    drop = drop_ep[index]
    reasons = duplicate_reasons(demos, dups, drop, reason)
    record = {"curate": dict(config or {}), "rule": dataclasses.asdict(rule), "reason": reason}
    record |= {"duplicates_of_base": dups} if dups else {}
    all_inputs: dict[str, str | Path] = {"demos": demos_path, **(inputs or {})}
    parts = []
    if base is not None:
        extra = {
            **base.extra,
            PRE_EPISODE: base.episode.astype(np.int64),
            PRE_STEP: base.step.astype(np.int32),
            "subset": np.full(base.n_steps, "base", dtype=object),
        }
        parts.append(dataclasses.replace(base, extra=extra))
        all_inputs["base"] = base_path  # type: ignore[assignment]
    if not drop.all():
        new = apply_drop(demos, drop, "renumber")
        subset = np.full(new.n_steps, "new", dtype=object)
        parts.append(dataclasses.replace(new, extra={**new.extra, "subset": subset}))
    counts = (demos.n_steps, int(drop.sum()), demos.n_episodes, int((~drop_ep).sum()))
    if not parts:
        if allow_empty:
            return CurateResult(None, None, *counts, reason + "; every demo dropped", dups)
        raise ElicitError(f"{reason}: every demonstration dropped, nothing to write")
    out = parts[0] if len(parts) == 1 else concat_demos(parts, renumber=True)
    per_step_score = np.asarray(scores.score, float)[index]
    log = pa.table(
        {
            "episode": pa.array(demos.episode[drop]),
            "operator": pa.array(demos.operator[drop].astype(str).tolist(), type=pa.string()),
            "step": pa.array(demos.step[drop]),
            "score": pa.array(per_step_score[drop]),
            "reason": pa.array(reasons[drop].tolist(), type=pa.string()),
        }
    )
    lp = log_path(out_path)
    header = make_header("filter-log", 1, config=record, inputs=all_inputs, n_dropped=counts[1])
    with atomic_paths([lp, out_path]) as (log_tmp, out_tmp):  # the pair is replaced together
        write_demos(out_tmp, out, config=record, inputs=all_inputs)
        write_parquet(log_tmp, log, header)
    return CurateResult(Path(out_path), lp, *counts, reason, dups)


def scores_path_for(out_path: str | Path) -> Path:
    """Sibling per-demonstration scores: ``x.parquet`` -> ``x.episode-scores.parquet``."""
    p = Path(out_path)
    return p.with_name(p.name.removesuffix(".parquet") + ".episode-scores.parquet")


def curate_file(
    config: CurateConfig,
    demos_path: str | Path,
    out_path: str | Path,
    *,
    rate: Literal["own", "m"] = "own",
    level: Literal["pair", "episode"] = "pair",
    scores_path: str | Path | None = None,
    thresholds: Thresholds | None = None,
    base_path: str | Path | None = None,
    policy_path: str | Path | None = None,
    progress: Callable[[int, float], None] | None = None,
    trajectories_path: str | Path | None = None,
) -> tuple[CurateResult, EpisodeScores]:
    """Score D_new with a curation method, cut, and write the kept demonstrations, the drop
    log and the per-demonstration scores (``<out>.episode-scores.parquet``).

    Args:
      config: method and settings.
      demos_path: D_new.
      out_path: the curated ``demos`` artifact.
      rate: ``own`` (the method's own cut) or ``m`` (drop as much as the M-filter would on
        ``scores_path``, at ``level``).
      level: the M-filter budget: ``pair`` (its incompatible pairs) or ``episode`` (its
        rejected demonstrations).
      scores_path: the compatibility scores of D_new (``rate="m"``).
      thresholds: (λ, η) of the M-filter (None: the scores' ``incompatible`` column).
      base_path: D_base: in DemInf's estimate, kept whole and placed first in the output.
      policy_path: Demo-SCORE: the training run to roll out.
      progress: Demo-SCORE: ``(epoch, success rate)`` after each checkpoint's rollouts.
      trajectories_path: CUPID: the recorded rollouts of ``policy_path``.
    """
    if rate not in ("own", "m"):
        raise ElicitError(f"unknown rate '{rate}' (own or m)")
    if rate == "m" and scores_path is None:
        raise ElicitError("--rate m drops as much as the M-filter: give --scores of D_new")
    rule: OwnRule | MatchedRule = OwnRule(config.deminf.drop_fraction)
    if rate == "m":
        rule = matched_rule(scores_path, level, thresholds)  # type: ignore[arg-type]
    scores = curation_scores(
        config, demos_path, base_path, policy_path, progress, trajectories_path
    )
    record = {"method": config.method, "rate": rate, "level": level, **method_config(config)}
    inputs: dict[str, str | Path] = {} if scores_path is None else {"scores": scores_path}
    if policy_path is not None and config.method in ("demo-score", "cupid"):
        inputs["policy"] = Path(policy_path) / "artifact.json"
    if trajectories_path is not None and config.method == "cupid":
        inputs["trajectories"] = trajectories_path
    result = curate_demos(
        scores, demos_path, out_path, rule, base_path, config=record, inputs=inputs
    )
    write_episode_scores(
        scores_path_for(out_path), scores, config=record, inputs={"demos": demos_path}
    )
    return result, scores
