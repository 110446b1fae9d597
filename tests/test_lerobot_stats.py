"""LeRobot-style statistics: hand-computed quantiles, aggregation, and an exported dataset's
stats against those LeRobot recorded for the same frames."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fixtures_data import (
    CAMERA,
    lerobot_episode,
    lerobot_reference_stats,
    write_lerobot_v30,
)

from elicit_jax.data.lerobot_export import export_lerobot
from elicit_jax.data.lerobot_stats import QUANTILE_KEYS, aggregate_stats, feature_stats


def test_histogram_quantiles_by_hand():
    # 0..99: 5000 bins of width ~99/5000 = 0.0198 from -1e-10; value v sits in bin
    # floor(v / 0.0198). q50 (target 50 values) completes inside the bin of value 49
    # (bin 2474): 49 values before, 1 inside, fraction 1 -> its upper edge 2475 * 0.0198.
    s = feature_stats(np.arange(100, dtype=np.float32))
    assert s["q50"] == pytest.approx([2475 * 99 / 5000], abs=1e-4)  # 49.005, not 49.5
    assert s["q10"] == pytest.approx([455 * 99 / 5000], abs=1e-4)  # value 9's bin, upper edge
    assert s["q90"] == pytest.approx([4495 * 99 / 5000], abs=1e-4)
    assert s["q99"] == pytest.approx([4950 * 99 / 5000], abs=1e-4)
    # q01 (target 1 value) is reached by the first bin already: the range's lower edge
    assert s["q01"] == pytest.approx([0.0], abs=1e-6)
    assert s["mean"] == pytest.approx([49.5]) and s["count"].tolist() == [100]
    # population std: sqrt(mean of squares 3283.5 - 49.5^2)
    assert s["std"] == pytest.approx([np.sqrt(3283.5 - 49.5**2)], rel=1e-6)
    assert s["min"].tolist() == [0.0] and s["max"].tolist() == [99.0]
    # a scalar feature keeps shape (1,), a vector (d,); one frame: quantiles = mean
    one = feature_stats(np.array([[1.0, 2.0]], np.float32))
    assert one["q01"].tolist() == [1.0, 2.0] and one["std"].tolist() == [0.0, 0.0]


def test_aggregate_pools_mean_and_variance_and_weights_quantiles():
    a = feature_stats(np.array([0.0, 2.0], np.float32))  # mean 1, std 1, n 2
    b = feature_stats(np.array([4.0, 4.0, 4.0, 4.0], np.float32))  # mean 4, std 0, n 4
    agg = aggregate_stats([a, b])
    # pooled over 0, 2, 4, 4, 4, 4: mean 3, variance (9 + 1 + 4 * 1) / 6
    assert agg["mean"] == pytest.approx([3.0])
    assert agg["std"] == pytest.approx([np.sqrt(14 / 6)])
    assert agg["count"].tolist() == [6] and agg["min"].tolist() == [0.0]
    # LeRobot's quantile aggregation: count-weighted mean of the episodes' quantiles
    assert agg["q50"] == pytest.approx((2 * a["q50"] + 4 * b["q50"]) / 6)


def _close(a, b):
    np.testing.assert_allclose(np.asarray(a, float), np.asarray(b, float), rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("camera", [False, True])
def test_exported_stats_equal_what_lerobot_recorded(tmp_path, camera):
    rng = np.random.default_rng(3)
    eps = [lerobot_episode(rng, i, 5 + 3 * i, success=i != 1) for i in range(4)]
    root = write_lerobot_v30(tmp_path / "src", eps, ["wipe"], camera=camera)
    recorded = json.loads((root / "meta/stats.json").read_text())
    out = tmp_path / "all"
    export_lerobot(root, out, [0, 1, 2, 3])
    ours = json.loads((out / "meta/stats.json").read_text())
    assert set(ours) == set(recorded)
    for feature, st in recorded.items():
        assert set(ours[feature]) == set(st) >= {"min", "max", "mean", "std", "count"}
        assert set(QUANTILE_KEYS) <= set(ours[feature])
        for key, value in st.items():
            _close(ours[feature][key], value)
    if camera:
        assert np.asarray(ours[CAMERA]["mean"]).shape == (3, 1, 1)
    # a selection: its stats are those of its own frames, per LeRobot's estimator
    export_lerobot(root, tmp_path / "sub", [1, 3])
    sub = json.loads((tmp_path / "sub/meta/stats.json").read_text())
    state = [lerobot_reference_stats(eps[i]["state"].astype(np.float32)) for i in (1, 3)]
    n1, n3 = len(eps[1]["state"]), len(eps[3]["state"])
    for key in ("q01", "q50", "q99"):
        _close(sub["observation.state"][key], (n1 * state[0][key] + n3 * state[1][key]) / (n1 + n3))
    both = np.concatenate([eps[1]["state"], eps[3]["state"]]).astype(np.float32)
    _close(sub["observation.state"]["mean"], both.mean(0))
    _close(sub["observation.state"]["std"], both.std(0))
    _close(sub["index"]["max"], [n1 + n3 - 1])  # renumbered frames
