"""Feedback primitives: top-k windows and base-demo retrieval (L2, DTW), by hand."""

import numpy as np
import pytest

from elicit_jax.compat.feedback import (
    Window,
    dtw_distance,
    episode_feedback,
    l2_distance,
    retrieve,
    top_windows,
)
from elicit_jax.errors import ElicitError


def test_top_windows_by_hand():
    m = np.array([1, 1, 0, 0, 1, 1, 1, 0.5, 1, 0])
    # 1 - M = [0, 0, 1, 1, 0, 0, 0, .5, 0, 1]; window-2 means by start:
    # [0, .5, 1, .5, 0, 0, .25, .25, .5]. Best: start 2 (1.0); it blocks starts 1..3.
    # Next: start 8 (0.5; start 1 and 3 are blocked), blocking 7..9. Then start 6 (0.25).
    assert top_windows(m, window=2, k=3) == [
        Window(2, 4, 1.0),
        Window(8, 10, 0.5),
        Window(6, 8, 0.25),
    ]
    # window 4, sums of 1-M by start: s=0: 2, s=1: 2, s=2: 2, s=3: 1, s=4: .5, s=5: .5,
    # s=6: 1.5. Greedy: start 0 (ties go to the earliest; mean .5) blocks starts 0..3, then
    # s=6 (mean .375) blocks 3..9: nothing is left, so only 2 windows although k = 5.
    assert len(top_windows(m, window=4, k=5)) == 2
    assert top_windows(m, window=4, k=5)[:2] == [Window(0, 4, 0.5), Window(6, 10, 0.375)]


def test_top_windows_short_episode_and_errors():
    # shorter than the window: one window over the whole episode, mean (1-M) = (0 + 1) / 2
    assert top_windows(np.array([1.0, 0.0]), window=10) == [Window(0, 2, 0.5)]
    with pytest.raises(ElicitError):
        top_windows(np.array([]))
    with pytest.raises(ElicitError):
        top_windows(np.ones(3), window=0)


def test_l2_distance_by_hand():
    # 1-D states. Query [1, 2]; episode [0, 1, 2, 5]: segment starts 0: |[0,1]-[1,2]| mean 1,
    # start 1: [1, 2] -> 0, start 2: [2, 5] -> (1 + 3) / 2 = 2. Best start 1, distance 0.
    q = np.array([[1.0], [2.0]])
    e = np.array([[0.0], [1.0], [2.0], [5.0]])
    assert l2_distance(q, e) == (0.0, 1, 3)
    # 2-D: query [[0, 0]], episode [[3, 4], [6, 8]] -> distances 5 and 10
    assert l2_distance(np.zeros((1, 2)), np.array([[3.0, 4.0], [6.0, 8.0]])) == (5.0, 0, 1)


def test_dtw_distance_by_hand():
    # query [0, 1, 2] vs episode [5, 0, 0, 1, 2, 9]: the free-start alignment matches
    # 0->0 (twice allowed but not needed), 1->1, 2->2, segment steps 2..4 (or 1..4), cost 0.
    q = np.array([[0.0], [1.0], [2.0]])
    e = np.array([[5.0], [0.0], [0.0], [1.0], [2.0], [9.0]])
    cost, start, stop = dtw_distance(q, e)
    assert cost == 0.0 and stop == 5 and start in (1, 2)
    # warping: query [0, 0, 3] vs episode [0, 3]: 0->0, 0->0, 3->3 costs 0, where L2 cannot
    # align (episode shorter): compares query windows [0, 0] (3 off) and [0, 3] (0) -> 0 too;
    # query [0, 3, 3, 3] vs [0, 3, 9]: DTW 0 (repeat 3), L2 best mean |[0,3,9]-[3,3,3]|=3
    # vs |[0,3,9]-[0,3,3]| = 2 -> 2
    q2 = np.array([[0.0], [3.0], [3.0], [3.0]])
    e2 = np.array([[0.0], [3.0], [9.0]])
    assert dtw_distance(q2, e2)[0] == 0.0
    assert l2_distance(q2, e2)[0] == pytest.approx(2.0)
    # cost per query step: query [1, 1], episode [0]: both steps align to 0, cost (1+1)/2 = 1
    assert dtw_distance(np.array([[1.0], [1.0]]), np.array([[0.0]])) == (1.0, 0, 1)


def test_dtw_matches_brute_force_recursion():
    def brute(q, e):
        c = np.linalg.norm(q[:, None] - e[None], axis=-1)
        d = np.full((len(q) + 1, len(e) + 1), np.inf)
        d[0, :] = 0.0
        for i in range(1, len(q) + 1):
            for j in range(1, len(e) + 1):
                d[i, j] = c[i - 1, j - 1] + min(d[i - 1, j], d[i, j - 1], d[i - 1, j - 1])
        return d[len(q), 1:].min() / len(q)

    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.normal(size=(rng.integers(1, 6), 2))
        e = rng.normal(size=(rng.integers(1, 9), 2))
        assert dtw_distance(q, e)[0] == pytest.approx(brute(q, e), abs=1e-12)


def test_retrieve_normalises_and_picks_nearest():
    # dim 0 varies on a scale of ~100, dim 1 on ~1: without normalisation dim 0 dominates.
    base = [
        np.array([[0.0, 0.0], [100.0, 0.0]]),  # episode 0
        np.array([[0.0, 1.0], [100.0, 1.0]]),  # episode 1
    ]
    # base std: dim 0 = 50, dim 1 = 0.5; mean (50, 0.5). Query (20, 1): normalised
    # (-0.6, 1); episode 0 states (-1, -1), (1, -1): nearest distance sqrt(.16 + 4) ~ 2.04;
    # episode 1 states (-1, 1), (1, 1): nearest sqrt(.16 + 0) = 0.4 -> episode 1, step 0
    (m,) = retrieve([np.array([[20.0, 1.0]])], base)
    assert (m.episode, m.start, m.stop) == (1, 0, 1)
    assert m.distance == pytest.approx(0.4)
    (d,) = retrieve([np.array([[20.0, 1.0]])], base, method="dtw")
    assert d.episode == 1 and d.distance == pytest.approx(0.4)
    with pytest.raises(ElicitError, match="unknown retrieval"):
        retrieve([base[0]], base, method="cosine")
    with pytest.raises(ElicitError, match="does not match"):
        retrieve([np.zeros((2, 3))], base)


def test_episode_feedback_maps_to_base_episode_ids():
    from elicit_jax.data.demos import from_episodes

    z = np.zeros((4, 1), np.float32)
    # base: episode 7 stays at 0, episode 9 climbs 0, 1, 2, 3 (1-D states)
    base = from_episodes(
        [
            {"obs": np.zeros((4, 1)), "action": z},
            {"obs": np.arange(4.0)[:, None], "action": z},
        ],
        episode_ids=[7, 9],
    )
    # the demo sits at 0 for 3 steps, then jumps to 2, 3 where it is incompatible (M = 0)
    obs = np.array([[0.0], [0.0], [0.0], [2.0], [3.0]])
    m = np.array([1.0, 1.0, 1.0, 0.0, 0.0])
    (fb,) = episode_feedback(m, obs, base, window=2, k=1)
    # worst window: steps 3..4 (mean 1 - M = 1); states [2, 3] match base episode 9 at 2..3
    assert (fb.window.start, fb.window.stop, fb.window.score) == (3, 5, 1.0)
    assert (fb.base_episode, fb.base_start, fb.base_stop) == (9, 2, 4)
    assert fb.distance == pytest.approx(0.0)
    with pytest.raises(ElicitError, match="compatibility values"):
        episode_feedback(m[:3], obs, base)
