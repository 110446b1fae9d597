"""The exact McNemar test of paired success outcomes, by hand."""

import pytest

from elicit_jax.errors import ElicitError
from elicit_jax.sim.compare import mcnemar_exact


def test_mcnemar_exact_by_hand():
    a = [1, 1, 1, 1, 1, 1, 1, 1, 0, 0]
    b = [1, 1, 0, 0, 0, 0, 0, 0, 0, 1]
    r = mcnemar_exact(a, b)
    # both 2, only a 6, only b 1, neither 1; d = 7 discordant, k = 1:
    # P[X <= 1] = (C(7,0) + C(7,1)) / 2^7 = 8 / 128 = 0.0625 -> p = 0.125
    assert (r.n, r.both, r.only_a, r.only_b, r.neither) == (10, 2, 6, 1, 1)
    assert r.p_value == pytest.approx(0.125)
    assert (r.rate_a, r.rate_b) == (0.8, 0.3)
    assert r.consistent(0.01) and not r.consistent(0.2)
    # 8 discordant pairs all one way: p = 2 / 2^8 = 0.0078125 < 0.01 -> rates differ
    strong = mcnemar_exact([True] * 8 + [False] * 4, [False] * 12)
    assert strong.p_value == pytest.approx(0.0078125) and not strong.consistent(0.01)
    # 7 all one way: p = 2 / 128 = 0.015625, not enough at 1%
    assert mcnemar_exact([1] * 7, [0] * 7).p_value == pytest.approx(0.015625)
    # 3 each way: 2 * (1 + 6 + 15 + 20) / 64 = 1.3125, capped at 1; the test is symmetric
    even = mcnemar_exact([1, 1, 1, 0, 0, 0, 1], [0, 0, 0, 1, 1, 1, 1])
    assert even.p_value == 1.0 and mcnemar_exact(b, a).p_value == r.p_value
    # identical outcomes: no discordant pair, p = 1
    assert mcnemar_exact(a, a).p_value == 1.0


def test_mcnemar_exact_rejects_bad_input():
    with pytest.raises(ElicitError, match="equally long"):
        mcnemar_exact([1, 0], [1])
    with pytest.raises(ElicitError, match="equally long"):
        mcnemar_exact([], [])
    with pytest.raises(ElicitError, match="booleans"):
        mcnemar_exact([1, 2], [0, 1])
