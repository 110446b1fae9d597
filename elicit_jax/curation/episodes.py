"""Per-demonstration quality scores and the two ways of cutting them.

Both curation baselines (:mod:`~elicit_jax.curation.deminf`, :mod:`~elicit_jax.curation.demo_score`)
end in the same place: one score per demonstration, higher is better, and a rule that drops
the lowest. :class:`EpisodeScores` holds the scores; :func:`select_drop` applies either the
method's own rule (:class:`OwnRule`: a score threshold, or a fixed fraction of demonstrations)
or a *matched* budget (:class:`MatchedRule`): as many pairs, or as many demonstrations, as the
M-filter drops, so a comparison between methods compares which data they drop rather than how
much. The artifact (kind ``episode-scores``) is one Parquet row per demonstration.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError

SCORES_KIND = "episode-scores"
SCHEMA_VERSION = 1


@dataclasses.dataclass(frozen=True)
class EpisodeScores:
    """One score per demonstration of a demos file (higher = keep).

    Attributes:
      method: ``deminf`` or ``demo-score``.
      episode: (E,) episode ids, in file order.
      operator: (E,) operator of each.
      length: (E,) steps of each.
      score: (E,) the method's score.
      threshold: the method's own score threshold (drop ``score <= threshold``), or None when
        its own rule is a fraction of demonstrations.
      report: method-specific diagnostics (estimates, classifier validation, ...).
      trusted: False when the method had no signal to rank with (then every score is equal and
        nothing is dropped); ``report["why"]`` says why.
    """

    method: str
    episode: np.ndarray
    operator: np.ndarray
    length: np.ndarray
    score: np.ndarray
    threshold: float | None = None
    report: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    trusted: bool = True

    def __post_init__(self) -> None:
        n = len(self.episode)
        for name in ("operator", "length", "score"):
            if len(getattr(self, name)) != n:
                raise ElicitError(f"episode scores: '{name}' has {len(getattr(self, name))} rows")
        if not np.isfinite(np.asarray(self.score, float)).all():
            raise ElicitError(f"{self.method}: non-finite demonstration scores")


@dataclasses.dataclass(frozen=True)
class OwnRule:
    """The method's own cut: ``score <= threshold`` when the scores carry a threshold, else
    the lowest ``drop_fraction`` of demonstrations (rounded to the nearest count)."""

    drop_fraction: float = 0.2

    def __post_init__(self) -> None:
        if not 0.0 <= self.drop_fraction < 1.0:
            raise ElicitError(f"drop fraction must be in [0, 1), got {self.drop_fraction}")


@dataclasses.dataclass(frozen=True)
class MatchedRule:
    """Drop lowest-scoring demonstrations until ``pairs`` pairs are dropped (pair-level
    budget: the last demonstration may overshoot it) or exactly ``episodes`` demonstrations."""

    pairs: int | None = None
    episodes: int | None = None

    def __post_init__(self) -> None:
        if (self.pairs is None) == (self.episodes is None):
            raise ElicitError("a matched budget is either pairs or episodes")


def episode_table(episode: np.ndarray, operator: np.ndarray) -> tuple[np.ndarray, ...]:
    """Per-step ``episode (N,)`` (contiguous) -> ``(ids (E,), operator (E,), length (E,),
    index (N,))`` in file order; ``index`` maps each step to its episode's position."""
    episode = np.asarray(episode)
    starts = np.concatenate([[0], np.flatnonzero(np.diff(episode)) + 1])
    ids = episode[starts]
    length = np.diff(np.append(starts, len(episode)))
    index = np.repeat(np.arange(len(ids)), length)
    return ids, np.asarray(operator)[starts].astype(str), length, index


def _lowest_first(scores: EpisodeScores) -> np.ndarray:
    """Positions of the demonstrations, lowest score first; ties by file order."""
    return np.argsort(np.asarray(scores.score, float), kind="stable")


def select_drop(scores: EpisodeScores, rule: OwnRule | MatchedRule) -> tuple[np.ndarray, str]:
    """Which demonstrations to drop.

    Returns:
      ``(drop (E,) bool, reason)``. An untrusted score (no signal) drops nothing.
    """
    n = len(scores.episode)
    drop = np.zeros(n, bool)
    if not scores.trusted:
        return drop, f"{scores.method} had no signal ({scores.report.get('why', '')}); kept all"
    order = _lowest_first(scores)
    if isinstance(rule, MatchedRule):
        if rule.episodes is not None:
            count = min(int(rule.episodes), n)
            why = f"{count} lowest-scoring demos (matched to the M-filter's {rule.episodes})"
        else:
            cum = np.cumsum(np.asarray(scores.length)[order])
            budget = int(rule.pairs or 0)
            count = int(np.searchsorted(cum, budget, side="left") + 1) if budget else 0
            count = min(count, n)
            why = (
                f"{count} lowest-scoring demos ({int(cum[count - 1]) if count else 0} pairs; "
                f"matched to the M-filter's {budget} pairs)"
            )
        drop[order[:count]] = True
        return drop, f"{scores.method}: {why}"
    if scores.threshold is not None:
        drop = np.asarray(scores.score, float) <= scores.threshold
        return drop, f"{scores.method}: score <= its threshold {scores.threshold:.4g}"
    count = round(rule.drop_fraction * n)
    drop[order[:count]] = True
    return drop, f"{scores.method}: lowest {count} of {n} demos ({rule.drop_fraction:g})"


def write_episode_scores(
    path: str | Path,
    scores: EpisodeScores,
    *,
    config: Mapping[str, Any],
    inputs: Mapping[str, str | Path],
    seed: int | None = None,
) -> None:
    """Write an ``episode-scores`` artifact: one row per demonstration, the method's
    threshold, trust flag and report in the header."""
    import pyarrow as pa

    from elicit_jax.artifact import make_header, write_parquet

    table = pa.table(
        {
            "episode": pa.array(np.asarray(scores.episode, np.int64)),
            "operator": pa.array([str(o) for o in scores.operator], type=pa.string()),
            "length": pa.array(np.asarray(scores.length, np.int64)),
            "score": pa.array(np.asarray(scores.score, np.float64)),
        }
    )
    header = make_header(
        SCORES_KIND,
        SCHEMA_VERSION,
        config=config,
        inputs=inputs,
        seed=seed,
        method=scores.method,
        threshold=scores.threshold,
        trusted=scores.trusted,
        report=dict(scores.report),
        n_episodes=len(scores.episode),
    )
    write_parquet(path, table, header)


def read_episode_scores(path: str | Path) -> EpisodeScores:
    """Read an ``episode-scores`` artifact back."""
    import pyarrow.parquet as pq

    from elicit_jax.artifact import read_artifact

    header = read_artifact(path, SCORES_KIND, SCHEMA_VERSION, what="episode scores")
    table = pq.read_table(path)
    return EpisodeScores(
        method=str(header["method"]),
        episode=table.column("episode").to_numpy(),
        operator=np.asarray(table.column("operator").to_pylist(), dtype=object),
        length=table.column("length").to_numpy(),
        score=table.column("score").to_numpy(),
        threshold=header.get("threshold"),
        report=header.get("report", {}),
        trusted=bool(header.get("trusted", True)),
    )
