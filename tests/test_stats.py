"""Seed statistics (p-values, Holm, the sign test) and the CLI's log set-up."""

import logging

import numpy as np
import pytest

from elicit_jax.runtime import configure_logging
from elicit_jax.stats import (
    format_diff,
    holm,
    holm_over,
    paired_t_interval,
    sample_std,
    sign_test_p,
    t_p_value,
)


def test_holm_by_hand():
    # m = 3 tests: 0.01 x 3 = 0.03, 0.03 x 2 = 0.06, 0.04 x 1 = 0.04 -> raised to 0.06
    out = holm([0.01, 0.04, 0.03, float("nan")])
    assert out[:3] == pytest.approx([0.03, 0.06, 0.06]) and np.isnan(out[3])
    assert holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])  # capped at 1
    assert holm([]) == []


def test_t_p_value_by_hand_and_no_test_without_spread():
    # t = 2 on 1 degree of freedom: 2 * (1/2 - atan(2)/pi)
    assert t_p_value(0.2, 0.1, 1) == pytest.approx(1 - 2 * np.arctan(2) / np.pi)
    assert np.isnan(t_p_value(0.2, 0.0, 4)) and np.isnan(t_p_value(0.2, 0.1, 0))
    for a in ([0.5, 0.7, 0.6], [0.5, 0.55, 0.6]):  # p 0.074 and 0.013
        d = paired_t_interval(a, [0.4, 0.4, 0.4])
        assert (d.p < 0.05) == d.excludes_zero  # the interval and the test agree


def test_sign_test_by_hand():
    assert sign_test_p([1.0, 2.0, 3.0]) == pytest.approx(0.25)  # 2 / 2**3
    assert sign_test_p([1.0] * 5) == pytest.approx(0.0625)
    assert sign_test_p([1.0, -1.0, 1.0]) == pytest.approx(1.0)
    assert sign_test_p([1.0, 0.0, 2.0]) == pytest.approx(0.5)  # the zero is dropped
    assert np.isnan(sign_test_p([0.0, 0.0]))


def test_a_difference_beyond_its_own_noise_loses_its_mark_among_many_tests():
    """Planted: p = 0.012 alone earns *, as one of five tests (Holm: 0.06) it does not."""
    strong = paired_t_interval([0.30, 0.32, 0.45], [0.1, 0.1, 0.1])
    weak = [paired_t_interval([0.1, 0.3, 0.2], [0.2, 0.1, 0.25]) for _ in range(4)]
    assert 0.01 < strong.p < 0.05 and strong.excludes_zero
    assert format_diff(strong).endswith(" *")
    adjusted = holm_over([strong, *weak, None])
    assert adjusted[0] == pytest.approx(5 * strong.p) and adjusted[-1] is None
    text = format_diff(strong, adjusted=adjusted[0])
    assert "*" not in text and f"(Holm p {adjusted[0]:.3f})" in text


def test_configure_logging_writes_records_to_the_file_only(tmp_path, capfd):
    logger = logging.getLogger("elicit_jax")
    saved = (list(logger.handlers), logger.level, logger.propagate)
    try:
        path = configure_logging(tmp_path / "logs" / "elicit-jax.log")
        logging.getLogger("elicit_jax.sim.mujoco").info("MuJoCo warning: unstable")
        for h in logger.handlers:
            h.flush()
        assert path == tmp_path / "logs" / "elicit-jax.log"
        assert "elicit_jax.sim.mujoco INFO MuJoCo warning: unstable" in path.read_text()
        out, err = capfd.readouterr()
        assert "unstable" not in out + err
        configure_logging(tmp_path / "again.log")  # a second call replaces, not adds
        ours = [h for h in logger.handlers if getattr(h, "elicit_jax_cli", False)]
        assert len(ours) == 1 and ours[0].baseFilename == str(tmp_path / "again.log")
    finally:
        for h in logger.handlers:
            if h not in saved[0]:
                h.close()
        logger.handlers[:] = saved[0]
        logger.setLevel(saved[1])
        logger.propagate = saved[2]


def test_reported_spreads_use_ddof_1(tmp_path):
    # lengths 2, 4, 6: mean 4, squared deviations 4 + 0 + 4 = 8, / (3 - 1) -> std 2 (ddof 0: 1.633)
    assert sample_std([2, 4, 6]) == pytest.approx(2.0)
    assert sample_std([7]) == 0.0 and sample_std([]) == 0.0  # no spread, never NaN
    import pandas as pd

    from elicit_jax.cli.info_demos import operator_stats

    rows = {"episode": [0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 2, 2], "operator": ["a"] * 12}
    path = tmp_path / "d.parquet"
    pd.DataFrame({**rows, "success": [True] * 12}).to_parquet(path)
    (stats,) = [r for r in operator_stats(path) if r["operator"] == "a"]
    assert (stats["mean_length"], stats["std_length"]) == (4.0, pytest.approx(2.0))
