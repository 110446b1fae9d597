"""Filter new demonstrations by compatibility (the paper's "M-Filtered") or by a baseline.

Levels:
  * ``pair``: drop single state-action pairs. Dropping pairs breaks step contiguity, which the
    demonstration artifact requires, so each episode is either *renumbered* (default: its
    remaining steps become 0..T'-1, fine for behaviour cloning, which the paper does) or
    *split* into its contiguous kept runs, each a new episode. Both modes add the extra
    columns ``pre_filter_episode`` and ``pre_filter_step`` (the ids in the scored file); the
    ``source_episode`` names of imported data are kept, so ``elicit-jax export`` still maps
    the result back to the original robomimic/LeRobot dataset.
  * ``episode``: drop whole demonstrations.

Methods (every baseline drops the same number of pairs/episodes as ``m`` would, so results
compare at an equal data budget):
  * ``m``: incompatible pairs (``ℓ > λ`` and ``ν < η``); episodes rejected by the 5% rule;
  * ``random``: that many pairs / episodes uniformly at random (seeded);
  * ``shortest`` / ``longest``: whole episodes by length, until the budget is reached (at pair
    level, until at least as many pairs are dropped);
  * ``likelihood``: the pairs / episodes (by mean ℓ) of highest likelihood error, novelty
    ignored;
  * ``novelty``: the pairs / episodes (by mean ν) of highest novelty — the usual
    ensemble-disagreement filter, which treats disagreement as bad data where M welcomes it.

The base demonstrations, when given, are kept whole and concatenated first (episode ids are
then renumbered 0..E-1; the extra column ``subset`` says ``base`` or ``new``). Every dropped
pair is logged with its reason in a sibling ``<out>.dropped.parquet`` (kind ``filter-log``).

With an :class:`ExportSpec` (episode level, no base), the kept episodes are also handed to the
foundation's exporter (:func:`elicit_jax.data.convert.export_dataset`): a copy of the original
robomimic file with a new ``mask/<key>`` listing them, or a LeRobot dataset / episode list
(``.json``). This maps back through the ``source_episode`` names recorded at import.

Example:
    >>> result = filter_demos("scores.parquet", "new.parquet", "filtered.parquet",
    ...                       FilterConfig(level="episode"), base_path="base.parquet")
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal

import numpy as np

from elicit_jax.artifact import (
    atomic_paths,
    make_header,
    matches_recorded,
    refuse_overwriting_inputs,
    write_parquet,
)
from elicit_jax.compat.measures import check_accept_fraction, is_incompatible
from elicit_jax.compat.thresholds import Thresholds, config_fields, from_config_fields
from elicit_jax.data.duplicates import drop_rows, duplicate_reasons, duplicates_of
from elicit_jax.errors import ElicitError

METHODS = ("m", "random", "shortest", "longest", "likelihood", "novelty")
LOG_KIND = "filter-log"
PRE_EPISODE = "pre_filter_episode"
PRE_STEP = "pre_filter_step"


@dataclasses.dataclass(frozen=True)
class FilterConfig:
    """How to filter.

    Attributes:
      level: ``pair`` or ``episode``.
      method: one of :data:`METHODS`.
      pair_mode: ``renumber`` or ``split`` (pair level only).
      thresholds: (λ, η) to judge the pairs by (None: the ``incompatible`` column of the
        scores, judged under the thresholds they were scored with).
      accept_fraction: the 5% rule's fraction (episode level).
      seed: seed of the ``random`` baseline.
    """

    level: Literal["pair", "episode"] = "pair"
    method: str = "m"
    pair_mode: Literal["renumber", "split"] = "renumber"
    thresholds: Thresholds | None = None
    accept_fraction: float = 0.05
    seed: int = 0

    def __post_init__(self) -> None:
        if self.level not in ("pair", "episode"):
            raise ElicitError(f"unknown level '{self.level}' (choose pair or episode)")
        if self.method not in METHODS:
            raise ElicitError(f"unknown method '{self.method}' (choose {', '.join(METHODS)})")
        if self.pair_mode not in ("renumber", "split"):
            raise ElicitError(f"unknown pair mode '{self.pair_mode}' (choose renumber or split)")
        if self.thresholds is not None and not isinstance(self.thresholds, Thresholds):
            raise ElicitError(f"thresholds must be a Thresholds value, got {self.thresholds!r}")
        check_accept_fraction(self.accept_fraction)

    def to_dict(self) -> dict[str, Any]:
        """JSON form, as artifacts and pipeline stage configs store it (the thresholds as
        ``lambda_`` and ``eta``, :func:`~elicit_jax.compat.thresholds.config_fields`)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        thresholds = d.pop("thresholds")
        return {**d, **config_fields(thresholds, key="lambda_")}

    @classmethod
    def from_dict(
        cls, data: Mapping[str, Any], thresholds: Thresholds | None = None
    ) -> FilterConfig:
        """Inverse of :meth:`to_dict`; ``thresholds``, when given, replace the stored ones."""
        d = dict(data)
        stored = from_config_fields(d, "the filter config", key="lambda_")
        return cls(**d, thresholds=thresholds if thresholds is not None else stored)


def _episode_index(episode: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ids, index = np.unique(episode, return_inverse=True)
    return ids, index


def drop_mask(scores: dict[str, np.ndarray], config: FilterConfig) -> tuple[np.ndarray, str]:
    """Which pairs to drop, and why.

    Args:
      scores: per-pair columns ``episode``, ``likelihood``, ``novelty``, ``incompatible``.
      config: level, method, thresholds, seed.

    Returns:
      ``(drop (N,) bool, reason)``.
    """
    ell, nu = np.asarray(scores["likelihood"]), np.asarray(scores["novelty"])
    if config.thresholds is not None:
        inc = is_incompatible(ell, nu, *config.thresholds.pair)
    else:
        inc = np.asarray(scores["incompatible"], bool)
    ids, index = _episode_index(np.asarray(scores["episode"]))
    lengths = np.bincount(index, minlength=len(ids))
    n_inc = np.bincount(index, weights=inc, minlength=len(ids))
    rejected = n_inc > config.accept_fraction * lengths
    f = config.accept_fraction
    if config.level == "pair":
        budget = int(inc.sum())
        if config.method == "m":
            return inc, "incompatible (likelihood error > lambda in a familiar state)"
        if config.method == "random":
            drop = np.zeros(len(ell), bool)
            rng = np.random.default_rng(config.seed)
            drop[rng.choice(len(ell), size=budget, replace=False)] = True
            return drop, f"random pair (seed {config.seed}, budget {budget})"
        if config.method in ("likelihood", "novelty"):
            key = ell if config.method == "likelihood" else nu
            drop = np.zeros(len(ell), bool)
            drop[np.argsort(-key, kind="stable")[:budget]] = True
            return drop, f"top-{budget} {config.method}"
        order = _by_length(lengths, config.method)
        cum = np.cumsum(lengths[order])
        n_eps = int(np.searchsorted(cum, budget, side="left") + 1) if budget else 0
        return np.isin(index, order[:n_eps]), f"{config.method} episodes (pair budget {budget})"
    budget = int(rejected.sum())
    if config.method == "m":
        chosen = np.flatnonzero(rejected)
        why = f"episode rejected: more than {100 * f:g}% of its pairs incompatible"
    elif config.method == "random":
        rng = np.random.default_rng(config.seed)
        chosen = rng.choice(len(ids), size=budget, replace=False)
        why = f"random episode (seed {config.seed}, budget {budget})"
    elif config.method in ("likelihood", "novelty"):
        key = ell if config.method == "likelihood" else nu
        mean = np.bincount(index, weights=key, minlength=len(ids)) / lengths
        chosen = np.argsort(-mean, kind="stable")[:budget]
        why = f"top-{budget} episodes by mean {config.method}"
    else:
        chosen = _by_length(lengths, config.method)[:budget]
        why = f"{config.method} episode (budget {budget})"
    return np.isin(index, chosen), why


def _by_length(lengths: np.ndarray, method: str) -> np.ndarray:
    """Episode indices shortest-first (or longest-first); ties by position."""
    key = lengths if method == "shortest" else -lengths
    return np.argsort(key, kind="stable")


def apply_drop(demos: Any, drop: np.ndarray, pair_mode: str = "renumber") -> Any:
    """Demos without the dropped rows, with contiguous steps (see module docstring)."""
    keep = ~np.asarray(drop, bool)
    if not keep.any():
        raise ElicitError("the filter drops every pair: nothing left to write")
    extra = dict(demos.extra)
    extra[PRE_EPISODE] = demos.episode.astype(np.int64)
    extra[PRE_STEP] = demos.step.astype(np.int32)
    kept = dataclasses.replace(demos, extra=extra).select(keep)
    if pair_mode == "split":
        gap = np.diff(kept.extra[PRE_STEP]) != 1
        new_ep = np.concatenate([[True], (np.diff(kept.episode) != 0) | gap])
        kept = dataclasses.replace(kept, episode=np.cumsum(new_ep).astype(np.int64) - 1)
    starts = np.concatenate([[0], np.flatnonzero(np.diff(kept.episode)) + 1])
    pos = np.arange(kept.n_steps) - np.repeat(starts, np.diff(np.append(starts, kept.n_steps)))
    return dataclasses.replace(kept, step=pos.astype(np.int32))


@dataclasses.dataclass(frozen=True)
class ExportSpec:
    """Also export the kept episodes to their source dataset's format.

    Attributes:
      format: ``robomimic`` (a copy of the source with ``mask/<mask_key>``) or ``lerobot``
        (a new dataset folder, or an episode list when ``out`` ends in ``.json``).
      out: where to write it.
      mask_key: robomimic: the new filter key.
      source: the original dataset (default: the one recorded at import).
      overwrite: replace an existing ``out`` (a file, or an earlier LeRobot export).
    """

    format: Literal["robomimic", "lerobot"]
    out: str
    mask_key: str | None = None
    source: str | None = None
    overwrite: bool = False


@dataclasses.dataclass(frozen=True)
class FilterResult:
    """Counts of a filtering run."""

    out_path: Path
    log_path: Path
    pairs_in: int
    pairs_dropped: int
    episodes_in: int
    episodes_out: int
    reason: str
    export: dict[str, Any] | None = None
    duplicates: dict[int, int] = dataclasses.field(default_factory=dict)
    """Episodes of D_new dropped as identical to D_base's: new id -> base id."""


def log_path(out_path: str | Path) -> Path:
    """Sibling drop log: ``x.parquet`` -> ``x.dropped.parquet``."""
    p = Path(out_path)
    return p.with_name(p.name.removesuffix(".parquet") + ".dropped.parquet")


def check_scores_match(scores_header: dict, scores: dict, demos: Any, demos_path: Path) -> None:
    """Error unless the scores were computed on exactly these demonstrations."""
    recorded = scores_header.get("inputs", {}).get("demos", {}).get("sha256")
    if recorded and not matches_recorded(recorded, demos_path):
        raise ElicitError(
            "these scores were computed on a different demonstrations file (sha256 mismatch)",
            demos_path,
        )
    if len(scores["episode"]) != demos.n_steps or not np.array_equal(
        np.asarray(scores["episode"]), demos.episode
    ):
        raise ElicitError("scores and demonstrations do not line up row by row", demos_path)


def filter_demos(
    scores_path: str | Path,
    demos_path: str | Path,
    out_path: str | Path,
    config: FilterConfig,
    *,
    base_path: str | Path | None = None,
    export: ExportSpec | None = None,
) -> FilterResult:
    """Filter ``demos_path`` by its scores; write the result and the drop log.

    Args:
      scores_path: the ``scores`` artifact of ``demos_path``.
      demos_path: D_new.
      out_path: the filtered demonstrations (``demos`` artifact).
      config: level, method, thresholds.
      base_path: D_base, kept whole and placed first.
      export: also export the kept episodes (episode level, without ``base_path``).

    Returns:
      A :class:`FilterResult`.
    """
    from elicit_jax.compat.score_file import read_scores
    from elicit_jax.data.demos import read_demos, write_demos

    demos_path = Path(demos_path)
    refuse_overwriting_inputs(
        [out_path, log_path(out_path)],
        [scores_path, demos_path, base_path, *([export.source] if export else [])],
    )
    _check_export(export, config, base_path)
    header, scores = read_scores(scores_path)
    demos = read_demos(demos_path)
    check_scores_match(header, scores, demos, demos_path)
    drop, reason = drop_mask(scores, config)
    base = None if base_path is None else read_demos(base_path)
    dups = {} if base is None else duplicates_of(demos, base)
    reasons = duplicate_reasons(demos, dups, drop, reason)
    drop = drop | drop_rows(demos, dups)
    inputs: dict[str, Path] = {"scores": Path(scores_path), "demos": demos_path}
    if base_path is not None:
        inputs["base"] = Path(base_path)
    new, out = _kept_demos(demos, drop, config, base)
    cfg = config.to_dict()
    record = {"filter": cfg} | ({"duplicates_of_base": dups} if dups else {})
    lp = log_path(out_path)
    with atomic_paths([lp, out_path]) as (log_tmp, out_tmp):  # the pair is replaced together
        write_demos(out_tmp, out, config=record, inputs=inputs, seed=config.seed)
        _write_drop_log(log_tmp, demos, scores, drop, reasons, cfg, inputs)
    return FilterResult(
        Path(out_path),
        lp,
        demos.n_steps,
        int(drop.sum()),
        demos.n_episodes,
        new.n_episodes if new is not None else 0,
        reason,
        None if export is None else _export_kept(out_path, export),
        dups,
    )


def _check_export(export: ExportSpec | None, config: FilterConfig, base_path: Any) -> None:
    """An export selects whole demos of one source dataset: episode level, no base."""
    if export is None:
        return
    if config.level != "episode" or base_path is not None:
        raise ElicitError(
            "exporting to robomimic/LeRobot needs --level episode and no --base (a mask "
            "or episode list selects whole demos of one source dataset)"
        )
    if export.format not in ("robomimic", "lerobot"):
        raise ElicitError(f"unknown export format '{export.format}' (robomimic or lerobot)")


def _kept_demos(demos: Any, drop: np.ndarray, config: FilterConfig, base: Any) -> tuple[Any, Any]:
    """``(new, out)``: the kept new demos (None when all are dropped beside a base) and what
    is written: the base, kept whole and placed first, then the kept new ones."""
    from elicit_jax.data.demos import concat_demos

    new = None
    if not drop.all() or base is None:
        new = apply_drop(demos, drop, config.pair_mode if config.level == "pair" else "renumber")
        new = dataclasses.replace(
            new, extra={**new.extra, "subset": np.full(new.n_steps, "new", dtype=object)}
        )
    if base is None:
        return new, new
    base_extra = {
        **base.extra,
        PRE_EPISODE: base.episode.astype(np.int64),
        PRE_STEP: base.step.astype(np.int32),
        "subset": np.full(base.n_steps, "base", dtype=object),
    }
    parts = [dataclasses.replace(base, extra=base_extra)] + ([new] if new is not None else [])
    return new, concat_demos(parts, renumber=True)


def _write_drop_log(
    lp: Path,
    demos: Any,
    scores: dict[str, np.ndarray],
    drop: np.ndarray,
    reasons: np.ndarray,
    cfg: dict[str, Any],
    inputs: dict[str, Path],
) -> None:
    """Write every dropped pair, with its scores and reason, to ``lp``."""
    import pyarrow as pa

    log = pa.table(
        {
            "episode": pa.array(demos.episode[drop]),
            "operator": pa.array(demos.operator[drop].astype(str).tolist(), type=pa.string()),
            "step": pa.array(demos.step[drop]),
            "likelihood": pa.array(np.asarray(scores["likelihood"])[drop]),
            "novelty": pa.array(np.asarray(scores["novelty"])[drop]),
            "compatibility": pa.array(np.asarray(scores["compatibility"])[drop]),
            "reason": pa.array(reasons[drop].tolist(), type=pa.string()),
        }
    )
    write_parquet(
        lp,
        log,
        make_header(LOG_KIND, 1, config=cfg, inputs=inputs, n_dropped=int(drop.sum())),
    )


def _export_kept(out_path: str | Path, export: ExportSpec) -> dict[str, Any]:
    """Hand the written selection to the dataset exporter (a robomimic mask, a LeRobot set)."""
    from elicit_jax.data.export import export_dataset
    from elicit_jax.data.export_config import ExportConfig

    return export_dataset(
        ExportConfig(
            selection=str(out_path),
            format=export.format,
            out=str(export.out),
            mask_key=export.mask_key,
            source=export.source,
            overwrite=export.overwrite,
        )
    )
