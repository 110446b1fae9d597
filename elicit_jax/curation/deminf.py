"""DemInf (Hejna et al., 2025, "Robot Data Curation with Mutual Information Estimators"):
score each demonstration by its contribution to the mutual information between states and
actions of the whole dataset, and drop the lowest.

High I(S; A) = H(S) − H(A | S) means varied states and actions that are predictable from the
state. DemInf estimates it with the KSG k-nearest-neighbour estimator
(:mod:`~elicit_jax.curation.ksg`) over every state-action pair of the dataset; each pair's term
of the estimator is its contribution, and a demonstration's score is the mean term of its
pairs. A demonstration whose actions disagree with what the rest of the data does in the same
states has wide joint neighbourhoods but crowded state neighbourhoods, hence low terms.

Our version, for low-dimensional state data (docs/curation.md lists what we simplified):

* the dataset is D_base ∪ D_new when D_base is given (the data the next policy trains on; a
  demonstration is judged against the base data as well as its own operator's), and only the
  D_new demonstrations are scored and dropped;
* states (the observation vector) and actions are standardised per dimension over that
  dataset; DemInf's optional learned (VAE) embeddings are not used;
* the estimate is exact over all pairs (no mini-batch subsampling), averaged over k = 5, 6, 7
  as in the authors' release; a jitter of 1e-5 standard deviations (seeded) breaks exact ties,
  as Kraskov et al. recommend for data with repeated values.

Example:
    >>> scores = deminf_scores(new, base, DemInfConfig())
    >>> scores.score          # (E,) mean KSG term per D_new demonstration, in nats
"""

from __future__ import annotations

import dataclasses

import numpy as np

from elicit_jax.curation.episodes import EpisodeScores, episode_table
from elicit_jax.curation.ksg import ksg_terms
from elicit_jax.errors import ElicitError


@dataclasses.dataclass(frozen=True)
class DemInfConfig:
    """DemInf settings.

    Attributes:
      ks: neighbour counts; each pair's term is averaged over them.
      drop_fraction: the method's own cut: the lowest-scoring fraction of D_new's
        demonstrations (DemInf ranks and prescribes no threshold; 0.2 is our default).
      jitter: standard deviation of the tie-breaking noise, in standardised units.
      seed: seed of that noise.
      chunk: query rows per step of the neighbour search.
    """

    ks: tuple[int, ...] = (5, 6, 7)
    drop_fraction: float = 0.2
    jitter: float = 1e-5
    seed: int = 0
    chunk: int = 256

    def __post_init__(self) -> None:
        object.__setattr__(self, "ks", tuple(int(k) for k in self.ks))
        if not self.ks or min(self.ks) < 1:
            raise ElicitError(f"deminf: ks must be positive neighbour counts, got {self.ks}")
        if not 0.0 <= self.drop_fraction < 1.0:
            raise ElicitError(f"deminf: drop_fraction must be in [0, 1), got {self.drop_fraction}")
        if self.jitter < 0:
            raise ElicitError(f"deminf: jitter must be >= 0, got {self.jitter}")


def standardise(x: np.ndarray) -> np.ndarray:
    """Per-column ``(x − mean) / std``; constant columns become 0."""
    x = np.asarray(x, np.float64)
    std = x.std(axis=0)
    return ((x - x.mean(axis=0)) / np.where(std > 1e-12, std, 1.0)).astype(np.float32)


def deminf_scores(new, base=None, config: DemInfConfig = DemInfConfig()) -> EpisodeScores:
    """Score the demonstrations of ``new`` by their mean KSG term over ``base ∪ new``.

    Args:
      new: :class:`~elicit_jax.data.demos.Demos` to score (D_new).
      base: optional D_base, part of the estimate but not scored.
      config: estimator settings.

    Returns:
      :class:`EpisodeScores` of ``new`` (no threshold: DemInf ranks; the cut is a fraction).
    """
    parts = [new] if base is None else [base, new]
    obs = np.concatenate([p.obs for p in parts])
    action = np.concatenate([p.action for p in parts])
    if base is not None and (base.obs_dim, base.action_dim) != (new.obs_dim, new.action_dim):
        raise ElicitError(
            f"D_base has obs/action dims {base.obs_dim}/{base.action_dim}, D_new "
            f"{new.obs_dim}/{new.action_dim}"
        )
    rng = np.random.default_rng(config.seed)
    s = standardise(obs)
    a = standardise(action)
    if config.jitter:
        s = s + (config.jitter * rng.standard_normal(s.shape)).astype(np.float32)
        a = a + (config.jitter * rng.standard_normal(a.shape)).astype(np.float32)
    terms = ksg_terms(s, a, config.ks, config.chunk).mean(axis=1)
    n_base = 0 if base is None else base.n_steps
    new_terms = terms[n_base:]
    ids, ops, length, index = episode_table(new.episode, new.operator)
    score = np.bincount(index, weights=new_terms, minlength=len(ids)) / length
    report = {
        "mi_estimate": float(terms.mean()),
        "n_pairs": len(terms),
        "n_base_pairs": n_base,
        "ks": list(config.ks),
        "new_mean_term": float(new_terms.mean()),
    }
    if base is not None:
        b_ids, _, b_len, b_index = episode_table(base.episode, base.operator)
        b_score = np.bincount(b_index, weights=terms[:n_base], minlength=len(b_ids)) / b_len
        report["base_demo_scores"] = {
            "mean": float(b_score.mean()),
            "min": float(b_score.min()),
            "q05": float(np.quantile(b_score, 0.05)),
        }
    return EpisodeScores("deminf", ids, ops, length, score, threshold=None, report=report)
