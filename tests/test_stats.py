"""Seed statistics (paired bootstrap) and the CLI's log set-up."""

import logging

import numpy as np
import pytest

from elicit_jax.errors import ElicitError
from elicit_jax.runtime import configure_logging
from elicit_jax.stats import paired_difference, sample_std


def test_paired_difference_per_collection_seed_and_mean():
    new = {1: [30.0, 40.0], 2: [50.0, 50.0, 56.0], 3: [20.0]}
    ref = {1: [40.0, 40.0], 2: [60.0, 54.0], 3: [30.0, 34.0, 26.0]}
    d = paired_difference(new, ref, n_boot=2000)
    # 35 - 40 = -5; 52 - 57 = -5; 20 - 30 = -10 -> mean -20/3
    np.testing.assert_allclose(d.per_key, [-5.0, -5.0, -10.0])
    assert d.keys == (1, 2, 3)
    assert d.mean == pytest.approx(-20.0 / 3.0)
    assert d.low <= d.mean <= d.high < 0.0 and d.excludes_zero
    assert d.low >= -14.0  # the most negative resample: -10, -10 and 20 - 34 = -14
    assert d.describe() == f"{d.mean:+.1f} [{d.low:+.1f}, {d.high:+.1f}]"
    again = paired_difference(new, ref, n_boot=2000)
    assert (again.low, again.high) == (d.low, d.high)  # deterministic given the seed


def test_paired_difference_interval_covers_zero_when_signs_disagree():
    new = {1: [10.0, 20.0, 30.0], 2: [60.0, 70.0, 80.0], 3: [40.0, 40.0, 40.0]}
    ref = {1: [40.0, 40.0, 40.0], 2: [40.0, 40.0, 40.0], 3: [40.0, 40.0, 40.0]}
    d = paired_difference(new, ref, n_boot=4000)
    np.testing.assert_allclose(d.per_key, [-20.0, 30.0, 0.0])
    assert d.low < 0.0 < d.high and not d.excludes_zero


def test_paired_difference_without_spread_collapses_to_the_mean():
    d = paired_difference({1: [50.0, 50.0], 2: [30.0]}, {1: [40.0], 2: [40.0, 40.0]})
    assert d.per_key.tolist() == [10.0, -10.0]
    # resampling collection seeds alone spreads the mean over {-10, 0, 10}
    assert d.low == -10.0 and d.high == 10.0 and d.mean == 0.0


@pytest.mark.parametrize(
    ("new", "ref", "match"),
    [
        ({1: [1.0]}, {2: [1.0]}, "collection seeds differ"),
        ({}, {}, "no collection seeds"),
        ({1: []}, {1: [1.0]}, "needs at least one training seed"),
        ({1: [np.nan]}, {1: [1.0]}, "non-finite"),
    ],
)
def test_paired_difference_rejects_bad_input(new, ref, match):
    with pytest.raises(ElicitError, match=match):
        paired_difference(new, ref)


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
