"""Per-episode quality metrics and flags: hand-computed numbers, and the CLI on an imported
robomimic file (``quality`` then ``filter --method quality``)."""

import numpy as np
import pytest
from fixtures_data import cli_ok, write_robomimic
from typer.testing import CliRunner

from elicit_jax.cli import app
from elicit_jax.curation.quality import (
    QualityConfig,
    episode_metrics,
    neighbour_metrics,
    quality_metrics,
    read_quality,
    robust_z,
)
from elicit_jax.data.demos import from_episodes, read_demos


def test_episode_metrics_by_hand():
    cfg = QualityConfig()
    smooth = np.array([[0, 0, 1], [0.25, 0, 1], [0.5, 0, 1], [0.75, 0, 1]], float)
    m = episode_metrics(smooth, cfg)
    # second differences are 0; step 0 is idle (max-norm 0 < 0.02); jumps 0.25 < 0.5
    assert m == {"duration": 4, "jerk": 0.0, "idle_fraction": 0.25, "spikes": 0,
                 "gripper_chatter": 0}  # fmt: skip
    rough = np.array([[0, 0, 1], [1, 0, -1], [0, 0, 1], [0, 0, -1]], float)
    m = episode_metrics(rough, cfg)
    # second differences (-2, 0) and (1, 0): (4 + 1) / 2; idle steps 0, 2, 3; jumps 1, 1, 0;
    # gripper + - + -: 3 sign changes
    assert m == {"duration": 4, "jerk": 2.5, "idle_fraction": 0.75, "spikes": 2,
                 "gripper_chatter": 3}  # fmt: skip
    # a gripper flicker inside the deadband has no sign
    deadband = np.array([[0, 0, 1], [0, 0, 0.05], [0, 0, -0.05], [0, 0, 1]], float)
    assert episode_metrics(deadband, cfg)["gripper_chatter"] == 0


def test_robust_z_by_hand():
    z = robust_z(np.array([1, 2, 3, 4, 100.0]))  # median 3, MAD 1
    np.testing.assert_allclose(z, 0.6745 * np.array([-2, -1, 0, 1, 97]))
    z = robust_z(np.array([0, 0, 0, 0, 5.0]))  # MAD 0: mean absolute deviation 1
    np.testing.assert_allclose(z, [0, 0, 0, 0, 5 / 1.2533])
    assert not robust_z(np.ones(4)).any()


def test_neighbour_metrics_by_hand():
    # three one-step episodes at states 0, 1, 3 (std sqrt(14/9)), actions 0, 1, 0.5
    obs = np.array([[0.0], [1.0], [3.0]])
    act = np.array([[0.0], [1.0], [0.5]])
    var, dist = neighbour_metrics(obs, act, np.arange(3), QualityConfig(k=1, gripper_dim=None))
    std = np.std([0.0, 1.0, 3.0])
    np.testing.assert_allclose(dist, [1 / std, 1 / std, 2 / std], rtol=1e-5)
    np.testing.assert_allclose(var, [1.0, 1.0, 0.25], rtol=1e-6)


def smooth_episode(rng, t=30, spikes=()):
    """A smooth reach: ramped 2-D motion actions plus an always-closed gripper; ``spikes``
    are steps whose first motion dim jumps to -0.95 (at least 0.65 away from the rest)."""
    s = np.linspace(0, 1, t)[:, None]
    motion = 0.3 * np.hstack([np.sin(3 * s + rng.uniform(0, 0.2)), np.cos(2 * s)])
    motion[list(spikes), 0] = -0.95
    act = np.hstack([motion, np.ones((t, 1))])
    obs = np.cumsum(motion, axis=0) * 0.1 + rng.normal(0, 0.01, (t, 2))
    return {"obs": obs, "action": act}


def test_quality_flags_the_spiky_episode():
    rng = np.random.default_rng(0)
    eps = [smooth_episode(rng) for _ in range(7)] + [smooth_episode(rng, spikes=(10, 20))]
    q = quality_metrics(from_episodes(eps, operators="op"), QualityConfig())
    assert q.metrics["spikes"].tolist() == [0] * 7 + [4]  # two jumps up, two back down
    assert q.flags["spikes"].tolist() == [False] * 7 + [True]
    assert q.flags["jerk"][7] and q.flagged.tolist() == [False] * 7 + [True]
    assert q.reason[7].startswith("jerk") and "spikes 4 (robust z" in q.reason[7]
    assert q.reason[:7] == [""] * 7


def test_quality_needs_a_crowd():
    from elicit_jax.errors import ElicitError

    eps = [smooth_episode(np.random.default_rng(i)) for i in range(2)]
    with pytest.raises(ElicitError, match="at least 3 episodes"):
        quality_metrics(from_episodes(eps, operators="op"))


def test_quality_settings_errors_name_the_flag():
    from elicit_jax.errors import ElicitError

    with pytest.raises(ElicitError, match=r"z_threshold \(--z\) must be a positive .* got nan"):
        QualityConfig(z_threshold=float("nan"))
    with pytest.raises(ElicitError, match=r"spike_jump \(--spike-jump\) .* got -1$"):
        QualityConfig(spike_jump=-1.0)


def test_quality_cli_on_imported_robomimic(tmp_path):
    rng = np.random.default_rng(1)
    demos = {}
    for i in range(9):
        ep = smooth_episode(rng, t=30, spikes=(12,) if i == 4 else ())
        a = np.hstack([ep["action"][:, :2], np.zeros((30, 4)), ep["action"][:, 2:]])
        demos[f"demo_{i}"] = {
            "actions": a,
            "obs/eef_pos": np.hstack([ep["obs"], np.zeros((30, 1))]),
        }
    src = write_robomimic(tmp_path / "teleop.hdf5", demos)

    def ok(*args):
        return cli_ok(*args).output

    ok("import", src, "--obs-keys", "eef_pos", "-o", tmp_path / "all.parquet")
    out = ok("quality", tmp_path / "all.parquet", "-o", tmp_path / "q.parquet")
    assert "1 flagged" in out and "spikes" in out
    table = read_quality(tmp_path / "q.parquet")
    assert table["flagged"].tolist() == [i == 4 for i in range(9)]
    assert table.loc[4, "spikes"] == 2 and table.loc[4, "spikes_flag"]
    ok("filter", "--method", "quality", "--demos", tmp_path / "all.parquet",
       "-o", tmp_path / "kept.parquet")  # fmt: skip
    kept = read_demos(tmp_path / "kept.parquet")
    assert kept.n_episodes == 8
    assert 4 not in set(kept.extra["pre_filter_episode"].tolist())
    # info on the per-demo scores (kind episode-scores, like score's per-episode summary)
    out = ok("info", tmp_path / "kept.episode-scores.parquet")
    assert "quality scores per operator" in out
    row = next(line for line in out.splitlines() if " 9 " in line)
    assert row.split("│")[-2].strip() == "1"  # one demo at or below the cut
    r = CliRunner().invoke(app, ["quality", str(tmp_path / "all.parquet"), "-o",
                                 str(tmp_path / "all.parquet")])  # fmt: skip
    assert r.exit_code != 0 and "refusing" in str(r.exception)


def test_quality_cli_on_imported_lerobot(tmp_path):
    """LeRobot data in degree-like units: a 60° glitch in one episode is its only spike."""
    from fixtures_data import lerobot_episode, write_lerobot_v30

    rng = np.random.default_rng(0)
    eps = []
    for i in range(6):
        ep = lerobot_episode(rng, i, 20)
        ep["action"] = np.cumsum(rng.normal(0, 2.0, (20, 6)), axis=0)  # smooth-ish, degrees
        if i == 2:
            ep["action"][9, 1] += 60.0
        eps.append(ep)
    root = write_lerobot_v30(tmp_path / "ds", eps, ["wipe"])
    r = CliRunner().invoke(app, ["import", str(root), "-o", str(tmp_path / "d.parquet")])
    assert r.exit_code == 0, (r.output, r.exception)
    r = CliRunner().invoke(
        app,
        ["quality", str(tmp_path / "d.parquet"), "-o", str(tmp_path / "q.parquet"),
         "--no-gripper", "--spike-jump", "30", "--idle-eps", "0.5"],
    )  # fmt: skip
    assert r.exit_code == 0, (r.output, r.exception)
    table = read_quality(tmp_path / "q.parquet")
    assert table["spikes"].tolist() == [0, 0, 2, 0, 0, 0]
    assert table.loc[2, "spikes_flag"] and "spikes 2" in table.loc[2, "reason"]
