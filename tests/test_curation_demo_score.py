"""Demo-SCORE: the classifier must separate a toy success/failure set, cross-validated across
checkpoints; demos scored by their states' mean prediction; no signal -> nothing dropped."""

from __future__ import annotations

import numpy as np
import pytest

from elicit_jax.curation.classifier import ClassifierConfig, fit_classifiers, predict
from elicit_jax.curation.demo_score import (
    DemoScoreConfig,
    Rollouts,
    at_chance,
    score_demos,
    train_demo_score,
)
from elicit_jax.curation.episodes import OwnRule, select_drop
from elicit_jax.data.demos import from_episodes
from elicit_jax.errors import ElicitError

FAST = {"steps": 400, "eval_every": 50, "batch_size": 256}


def _toy_rollouts(rng, success_rates=(0.3, 0.5, 0.6), n=20, t=15):
    """Rollouts of 3 'checkpoints' on a 2-D state: successful rollouts visit x0 > 0.3,
    failed ones x0 < -0.3; x1 is noise."""
    success, ckpt, states, rollout = [], [], [], []
    r = 0
    for j, rate in enumerate(success_rates):
        outcome = np.arange(n) < round(rate * n)
        for ok in outcome:
            x0 = rng.uniform(0.3, 1.5, t) if ok else rng.uniform(-1.5, -0.3, t)
            states.append(np.stack([x0, rng.normal(size=t)], 1))
            rollout.append(np.full(t, r))
            success.append(ok)
            ckpt.append(j)
            r += 1
    return Rollouts(
        epochs=np.array([10, 20, 30]),
        success=np.array(success),
        checkpoint=np.array(ckpt),
        states=np.concatenate(states).astype(np.float32),
        rollout=np.concatenate(rollout),
    )


def test_classifier_separates_success_from_failure_states():
    rng = np.random.default_rng(0)
    cfg = ClassifierConfig(**FAST)
    x = np.concatenate([rng.normal([1, 0], 0.3, (200, 2)), rng.normal([-1, 0], 0.3, (200, 2))])
    y = np.arange(400) < 200
    val = np.concatenate([rng.normal([1, 0], 0.3, (50, 2)), rng.normal([-1, 0], 0.3, (50, 2))])
    val_y = np.arange(100) < 50
    # two candidate training sets: the first half of each class, and everything
    cands = [np.r_[0:100, 200:300], np.arange(400)]
    state, curve = fit_classifiers(cfg, x, y, cands, val, val_y)
    assert curve.shape == (2, 8)
    assert np.all(np.asarray(state.best_loss) < 0.3)
    for k in range(2):
        params = __import__("jax").tree.map(lambda a, k=k: a[k], state.best_params)
        p = predict(cfg, params, val)
        assert p[:50].mean() > 0.8 and p[50:].mean() < 0.2
    # the kept parameters are those of the lowest validation loss seen
    assert np.allclose(np.asarray(state.best_loss), curve.min(axis=1))


def test_demo_score_cross_validates_and_drops_failure_like_demos():
    rng = np.random.default_rng(1)
    rollouts = _toy_rollouts(rng)
    model = train_demo_score(rollouts, DemoScoreConfig(classifier=FAST))
    rep = model.report
    assert rep["validation_epoch"] == 30  # the last checkpoint validates
    assert [c["train_epoch"] for c in rep["candidates"]] == [10, 20]
    assert rep["chosen_train_epoch"] in (10, 20)
    assert rep["validation_balanced_accuracy"] == 1.0 and not at_chance(rep)
    assert 0.0 < model.threshold < 1.0
    # demos: 3 whose states look like successes, 2 like failures
    demos = []
    for ok in (True, False, True, False, True):
        x0 = rng.uniform(0.4, 1.2, 12) if ok else rng.uniform(-1.2, -0.4, 12)
        demos.append({"obs": np.stack([x0, rng.normal(size=12)], 1), "action": np.zeros((12, 1))})
    new = from_episodes(demos, operators="op")
    scores = score_demos(new, model, {})
    assert scores.trusted and scores.threshold == model.threshold
    drop, _ = select_drop(scores, OwnRule())
    assert np.flatnonzero(drop).tolist() == [1, 3]


def test_no_signal_when_every_candidate_is_one_class():
    rng = np.random.default_rng(2)
    rollouts = _toy_rollouts(rng, success_rates=(0.0, 1.0, 0.5))
    assert train_demo_score(rollouts, DemoScoreConfig(classifier=FAST)) is None
    new = from_episodes([{"obs": np.zeros((5, 2)), "action": np.zeros((5, 1))}], operators="a")
    scores = score_demos(new, None, {"checkpoints": []})
    assert not scores.trusted and "all successes or all failures" in scores.report["why"]
    drop, why = select_drop(scores, OwnRule())
    assert not drop.any() and "no signal" in why


def test_at_chance_flags_a_classifier_no_better_than_chance_on_held_out_rollouts():
    assert at_chance({"validation_balanced_accuracy": 0.5})
    assert at_chance({"validation_balanced_accuracy": 0.31})
    assert not at_chance({"validation_balanced_accuracy": 0.51})
    # one class among the held-out rollouts: the accuracy is of that class alone, not balanced
    assert not at_chance({"validation_balanced_accuracy": 0.4, "validation_one_class": True})
    assert not at_chance({})


def test_config_validation():
    with pytest.raises(ElicitError, match="rollouts"):
        DemoScoreConfig(rollouts=1)
    with pytest.raises(ElicitError, match="eval_every"):
        DemoScoreConfig(classifier={"steps": 10, "eval_every": 50})
    with pytest.raises(ElicitError, match=r"classifier\] unknown option\(s\) stepz"):
        DemoScoreConfig(classifier={"stepz": 10})
