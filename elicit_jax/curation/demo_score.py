"""Demo-SCORE (Chen et al., 2025, "Curating Demonstrations using Online Experience"): roll out
a policy trained on the demonstrations, learn which states lead to success, and drop the
demonstrations whose states look like failures.

1. **Rollouts.** The policy trained on the data to curate (in the filtering study: D_base ∪
   D_new, the "naive" policy) is rolled out from several of its training checkpoints on C
   MuJoCo, ``rollouts`` episodes each, from seeded initial states disjoint from the
   evaluation's. Every state the policy acted in is kept with its rollout's outcome.
2. **Classifier, cross-validated across checkpoints.** A small MLP
   (:mod:`~elicit_jax.curation.classifier`) is trained to tell states of successful rollouts
   from states of failed ones. As in the paper, a classifier is trained on the rollouts of one
   checkpoint and validated on the rollouts of *another* (here: the last checkpoint), so the
   early-stopped classifier captures what separates success from failure across policies
   rather than one policy's quirks; each earlier checkpoint is a candidate training set, and the
   candidate with the lowest validation loss is kept.
3. **Scores.** A demonstration's score is its states' mean predicted probability of success.
   The method's own threshold is the mean score of the chosen classifier's training rollouts
   (the authors' release); demonstrations at or below it are dropped.

Example:
    >>> scores = demo_score_scores("runs/naive", new, DemoScoreConfig(task="square-nut"))
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.curation.classifier import ClassifierConfig, fit_classifiers, predict
from elicit_jax.curation.episodes import EpisodeScores, episode_table
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.policy.base import Policy

SEED_STRIDE = 100_000


@dataclasses.dataclass(frozen=True)
class DemoScoreConfig:
    """Demo-SCORE settings.

    Attributes:
      task: the task to roll out on.
      rollouts: rollouts per checkpoint.
      checkpoints: epochs to roll out (empty: every saved epoch); the last is the validation
        checkpoint, each other one a candidate training set.
      policy_seed: training seed of a multi-seed run (None: its first seed).
      seed: initial states of checkpoint j are evaluation seeds ``seed + j`` (far from the
        evaluation's own, which use seeds < 50).
      horizon: control steps (0: the task's).
      threads: C MuJoCo threads or robosuite processes (0: one per CPU).
      classifier: the state classifier and its training (a mapping of its fields is accepted,
        as a ``[demo_score.classifier]`` table of a pipeline definition gives).
    """

    task: str = "square-nut"
    rollouts: int = 100
    checkpoints: tuple[int, ...] = ()
    policy_seed: int | None = None
    seed: int = 50
    horizon: int = 0
    threads: int = 0
    classifier: ClassifierConfig = dataclasses.field(default_factory=ClassifierConfig)

    def __post_init__(self) -> None:
        object.__setattr__(self, "checkpoints", tuple(int(c) for c in self.checkpoints))
        if isinstance(self.classifier, Mapping):
            names = {f.name for f in dataclasses.fields(ClassifierConfig)}
            unknown = sorted(set(self.classifier) - names)
            if unknown:
                raise ElicitError(
                    f"[demo_score.classifier] unknown option(s) {', '.join(unknown)} "
                    f"(allowed: {', '.join(sorted(names))})"
                )
            object.__setattr__(self, "classifier", ClassifierConfig(**self.classifier))
        if self.rollouts < 2:
            raise ElicitError(f"demo-score: rollouts must be at least 2, got {self.rollouts}")


@dataclasses.dataclass(frozen=True)
class Rollouts:
    """Rollout states of several checkpoints, flattened.

    Attributes:
      epochs: (C,) checkpoint epochs rolled out.
      success: (R,) outcome of each rollout.
      checkpoint: (R,) index into ``epochs`` of each rollout.
      states: (M, O) every state a policy acted in.
      rollout: (M,) the rollout of each state.
    """

    epochs: np.ndarray
    success: np.ndarray
    checkpoint: np.ndarray
    states: np.ndarray
    rollout: np.ndarray


def rollout_epochs(policy_dir: str | Path, config: DemoScoreConfig) -> tuple[int, list[int]]:
    """``(seed, epochs)`` to roll out: the configured epochs, or every saved one."""
    from elicit_jax.policy.checkpoint import list_checkpoints

    avail = list_checkpoints(policy_dir)
    seed = min(avail) if config.policy_seed is None else int(config.policy_seed)
    if seed not in avail:
        raise ElicitError(f"demo-score: no training seed {seed} (have {sorted(avail)})", policy_dir)
    saved = [int(c) for c in avail[seed] if c != "best"]
    epochs = list(config.checkpoints) or saved
    missing = sorted(set(epochs) - set(saved))
    if missing:
        raise ElicitError(f"demo-score: no checkpoint(s) {missing} (saved: {saved})", policy_dir)
    if len(set(epochs)) < 2:
        raise ElicitError(
            "demo-score cross-validates across checkpoints and needs at least two saved epochs "
            f"(have {saved}); train with checkpoint_every below the epoch count",
            policy_dir,
        )
    return seed, sorted(set(epochs))


def collect_rollouts(
    policy_dir: str | Path,
    config: DemoScoreConfig,
    progress: Callable[[int, float], None] | None = None,
) -> Rollouts:
    """Roll out every chosen checkpoint of ``policy_dir`` and keep the visited states.

    Args:
      policy_dir: a training run (the policy trained on the data being curated).
      config: which checkpoints, how many rollouts, from which initial states.
      progress: called with ``(epoch, success rate)`` after each checkpoint.
    """
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.evaluate import EVAL_SEED_BASE
    from elicit_jax.sim.registry import task_entry

    seed, epochs = rollout_epochs(policy_dir, config)
    task = make_task(config.task)
    horizon = config.horizon or task.config.horizon
    success, checkpoint, states, rollout = [], [], [], []
    for j, epoch in enumerate(epochs):
        policy = load_policy(policy_dir, epoch, seed=seed, task=task_entry(task.name)).policy
        init = EVAL_SEED_BASE + (config.seed + j) * SEED_STRIDE + np.arange(config.rollouts)
        out = _rollouts(task, policy, init, horizon, config.threads)
        mask = out["state_mask"]
        offset = j * config.rollouts
        success.append(np.asarray(out["success"], bool))
        checkpoint.append(np.full(config.rollouts, j))
        states.append(out["states"][mask])
        rollout.append(offset + np.nonzero(mask)[0])
        if progress is not None:
            progress(epoch, float(np.mean(out["success"])))
    return Rollouts(
        epochs=np.asarray(epochs),
        success=np.concatenate(success),
        checkpoint=np.concatenate(checkpoint),
        states=np.concatenate(states).astype(np.float32),
        rollout=np.concatenate(rollout),
    )


@dataclasses.dataclass(frozen=True)
class DemoScoreModel:
    """A trained Demo-SCORE classifier with its input normalisation and threshold."""

    config: ClassifierConfig
    params: Any
    mean: np.ndarray
    std: np.ndarray
    threshold: float | None
    report: dict[str, Any]

    def prob(self, states: np.ndarray) -> np.ndarray:
        """(M,) predicted probability of success for raw states ``(M, O)``."""
        return predict(self.config, self.params, (np.asarray(states) - self.mean) / self.std)


def _rollouts(task: Any, policy: Policy, seeds: np.ndarray, horizon: int, threads: int) -> dict:
    """Rollouts with recorded states on the task's simulator: C MuJoCo, or robosuite's
    worker processes (``threads`` of them; 0: one per CPU) for its tasks."""
    from elicit_jax.sim.evaluate import rollout_mujoco_policy

    if getattr(task, "backend", "") != "robosuite":
        return rollout_mujoco_policy(task, policy, seeds, horizon, threads, True)
    from elicit_jax.policy.base import jitted_act
    from elicit_jax.runtime import available_cpus
    from elicit_jax.sim.rollout_robosuite import rollout_policy, shared_pool

    workers = min(threads or available_cpus(), len(seeds))
    pool = shared_pool(task.spec, workers)
    return rollout_policy(task.spec, jitted_act(), policy, seeds, horizon, workers, pool, True)


def checkpoint_summary(rollouts: Rollouts) -> list[dict[str, int]]:
    """Per rolled-out checkpoint: its epoch, rollouts and successes."""
    return [
        {
            "epoch": int(e),
            "rollouts": int((rollouts.checkpoint == j).sum()),
            "successes": int(rollouts.success[rollouts.checkpoint == j].sum()),
        }
        for j, e in enumerate(rollouts.epochs)
    ]


def _rollout_means(prob: np.ndarray, rollout: np.ndarray, n: int) -> np.ndarray:
    counts = np.bincount(rollout, minlength=n)
    sums = np.bincount(rollout, weights=prob, minlength=n)
    return sums / np.maximum(counts, 1)


def train_demo_score(rollouts: Rollouts, config: DemoScoreConfig) -> DemoScoreModel | None:
    """Fit the cross-validated classifier; None when no checkpoint's rollouts hold both a
    success and a failure (nothing to learn from)."""
    cls = config.classifier
    states = rollouts.states
    mean = states.mean(axis=0)
    std = np.where(states.std(axis=0) > 1e-8, states.std(axis=0), 1.0)
    x = (states - mean) / std
    y = rollouts.success[rollouts.rollout]
    state_ckpt = rollouts.checkpoint[rollouts.rollout]
    val = len(rollouts.epochs) - 1
    per_ckpt = checkpoint_summary(rollouts)
    usable = [j for j in range(val) if 0 < per_ckpt[j]["successes"] < per_ckpt[j]["rollouts"]]
    report: dict[str, Any] = {
        "checkpoints": per_ckpt,
        "validation_epoch": int(rollouts.epochs[val]),
    }
    if not usable:
        return None
    val_rows = np.flatnonzero(state_ckpt == val)
    candidates = [np.flatnonzero(state_ckpt == j) for j in usable]
    fits, curve = fit_classifiers(cls, x, y, candidates, x[val_rows], y[val_rows])
    losses = np.asarray(fits.best_loss)
    best = int(np.argmin(losses))
    params = jax_index(fits.best_params, best)
    model = DemoScoreModel(cls, params, mean, std, None, report)
    n = len(rollouts.success)
    means = _rollout_means(model.prob(states), rollouts.rollout, n)
    train_ro = rollouts.checkpoint == usable[best]
    threshold = float(means[train_ro].mean())
    val_ro = rollouts.checkpoint == val
    pred = means[val_ro] > threshold
    truth = rollouts.success[val_ro]
    accs = [float((pred[truth == c] == c).mean()) for c in (True, False) if (truth == c).any()]
    report |= {
        "candidates": [
            {
                "train_epoch": int(rollouts.epochs[j]),
                "best_val_loss": float(losses[k]),
                "best_step": int(np.asarray(fits.best_step)[k]),
            }
            for k, j in enumerate(usable)
        ],
        "chosen_train_epoch": int(rollouts.epochs[usable[best]]),
        "threshold": threshold,
        "validation_balanced_accuracy": float(np.mean(accs)),
        "validation_one_class": len(accs) < 2,
        "validation_curve": curve[best].tolist(),
    }
    return dataclasses.replace(model, threshold=threshold, report=report)


def at_chance(report: dict[str, Any]) -> bool:
    """True when the classifier told held-out successful from failed rollouts no better than
    chance (balanced accuracy ≤ 0.5): its cut still applies, but its ranking of demos carries
    no evidence about success."""
    acc = report.get("validation_balanced_accuracy")
    return acc is not None and not report.get("validation_one_class", False) and acc <= 0.5


def jax_index(tree: Any, i: int) -> Any:
    """Entry ``i`` of every leaf of a K-batched pytree."""
    import jax

    return jax.tree.map(lambda a: a[i], tree)


def score_demos(new: Any, model: DemoScoreModel | None, report: dict[str, Any]) -> EpisodeScores:
    """Demo-SCORE scores of the demonstrations of ``new``: mean predicted success of their
    states; untrusted (all 0.5, nothing dropped) when there is no classifier."""
    ids, ops, length, index = episode_table(new.episode, new.operator)
    if model is None:
        why = "every candidate checkpoint's rollouts were all successes or all failures"
        return EpisodeScores(
            "demo-score",
            ids,
            ops,
            length,
            np.full(len(ids), 0.5),
            report={**report, "why": why},
            trusted=False,
        )
    score = np.bincount(index, weights=model.prob(new.obs), minlength=len(ids)) / length
    return EpisodeScores("demo-score", ids, ops, length, score, model.threshold, model.report)


def demo_score_scores(
    policy_dir: str | Path,
    new: Any,
    config: DemoScoreConfig,
    progress: Callable[[int, float], None] | None = None,
) -> EpisodeScores:
    """Roll out ``policy_dir``, fit the cross-validated classifier, score ``new``.

    Args:
      policy_dir: a training run with several saved epochs.
      new: :class:`~elicit_jax.data.demos.Demos` to score.
      config: settings.
      progress: called with ``(epoch, success rate)`` after each checkpoint's rollouts.
    """
    rollouts = collect_rollouts(policy_dir, config, progress)
    model = train_demo_score(rollouts, config)
    return score_demos(new, model, {"checkpoints": checkpoint_summary(rollouts)})
