"""Absurd numbers are refused where they enter, with one line saying what is wrong (issue #45,
items 9 and its "Also"): an observation of 1e30 at import, train and score; a learning rate of
inf or 1e30; a run whose loss becomes NaN; batch sizes and dropout passes that could only end
in an out-of-memory traceback."""

import numpy as np
import pytest
from fixtures_data import invoke, robomimic_demo, tiny_episodes, tiny_run, write_robomimic

from elicit_jax.data import validation
from elicit_jax.data.demos import from_episodes, write_demos
from elicit_jax.errors import ElicitError


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return tiny_run(tmp_path_factory.mktemp("absurd"))


def _one_line(r, path, *texts):
    assert isinstance(r.exception, ElicitError), (r.exception, r.output)
    msg = str(r.exception)
    assert msg.startswith(f"{path}: ") and "\n" not in msg, msg
    for text in texts:
        assert text in msg, msg
    return msg


def _robomimic_with_1e30(tmp_path):
    rng = np.random.default_rng(0)
    demos = {f"demo_{i}": robomimic_demo(rng, 12) for i in range(4)}
    demos["demo_2"]["obs/object"][5, 3] = 1e30
    return write_robomimic(tmp_path / "big.hdf5", demos)


def test_an_absurd_observation_is_refused_at_import(tmp_path):
    src = _robomimic_with_1e30(tmp_path)
    out = tmp_path / "d.parquet"
    r = invoke("import", src, "-o", out)
    # obs = eef_pos 3, eef_quat 4, gripper 2, object 14: object[3] is column 12
    _one_line(r, src, "obs[12] ('object'[3]) = 1e+30", "episode 2 (demo_2), step 5", "beyond")
    assert not out.exists()
    # --skip-bad-episodes leaves the episode out and names it
    r = invoke("import", src, "-o", out, "--skip-bad-episodes")
    assert r.exit_code == 0, r.output
    assert "demo_2: |value| > 1e+06 in obs at step 5" in r.output


def _demos_with_1e30(path, monkeypatch):
    """A demos file holding one obs of 1e30, written the way an older elicit-jax wrote it
    (without the magnitude check)."""
    eps = tiny_episodes()
    eps[1]["obs"][4, 2] = 1e30
    with monkeypatch.context() as m:
        m.setattr(validation, "MAX_MAGNITUDE", np.inf)
        write_demos(path, from_episodes(eps, operators="base"))
    return path


def test_an_absurd_observation_is_refused_by_train_and_named_by_score(run, tmp_path, monkeypatch):
    demos = _demos_with_1e30(tmp_path / "big.parquet", monkeypatch)
    r = invoke("train", "--demos", demos, "--out", tmp_path / "r", "--profile", "cpu")
    _one_line(r, demos, "obs[2] = 1e+30 at episode 1, step 4")
    assert not (tmp_path / "r").exists()
    out = tmp_path / "s.parquet"
    r = invoke("score", "--policy", run / "run", "--demos", demos, "-o", out)
    msg = _one_line(r, demos, "obs[2] = 1e+30 at episode 1, step 4")
    assert "checkpoint" not in msg and not out.exists()


@pytest.mark.parametrize("lr", ["inf", "1e30", "0", "-0.001", "nan"])
def test_a_learning_rate_that_cannot_train_is_refused_up_front(tmp_path, run, lr):
    out = tmp_path / "r"
    r = invoke("train", "--demos", run / "demos.parquet", "--out", out, "--lr", lr, "-q")
    assert isinstance(r.exception, ElicitError), r.output
    assert "lr must be a number in (0, 1]" in str(r.exception)
    assert not out.exists()


def test_a_run_whose_loss_turns_nan_fails_and_writes_nothing(tmp_path):
    """A planted divergence (the config's own check bypassed): no run directory, no best.npz
    holding the random initialisation, an error naming the run, seed and epoch."""
    from fixtures_data import tiny_train_config

    from elicit_jax.policy.train import check_losses, train_policy

    config = tiny_train_config(epochs=4, checkpoint_every=2)
    object.__setattr__(config, "lr", 1e30)
    out = tmp_path / "run"
    demos = from_episodes(tiny_episodes(), operators="base")
    with pytest.raises(ElicitError) as e:
        train_policy(demos, config, out, quiet=True)
    msg = str(e.value)
    assert msg.startswith(f"{out}: training diverged: seed 0's loss is not finite"), msg
    assert not out.exists() and not list(tmp_path.glob(".*run*"))
    # the check on its own: the first bad epoch of the chunk, val losses of NaN without a
    # validation split are not a divergence
    ok = np.ones((1, 2, 2))
    check_losses((0,), 2, ok, np.full_like(ok, np.nan), out)
    bad = ok.copy()
    bad[0, 1, 0] = np.inf
    with pytest.raises(ElicitError, match=r"seed 3's loss is not finite .* at epoch 4"):
        check_losses((3,), 4, bad, ok, out)
    with pytest.raises(ElicitError, match="at epoch 3"):
        check_losses((3,), 4, ok, np.where(bad > 1, np.nan, ok)[:, ::-1], out)


def test_batch_sizes_and_dropout_passes_that_cannot_fit_are_one_line(run, tmp_path):
    r = invoke(
        "train", "--demos", run / "demos.parquet", "--out", tmp_path / "r", "--batch-size",
        "100000000", "-q",
    )  # fmt: skip
    assert isinstance(r.exception, ElicitError)
    assert "batch_size must be in 1..65536, got 100000000" in str(r.exception)
    r = invoke(
        "score", "--policy", run / "run", "--demos", run / "demos.parquet", "-o",
        tmp_path / "s.parquet", "--dropout-samples", "100000",
    )  # fmt: skip
    assert isinstance(r.exception, ElicitError)
    assert "dropout samples must be in 0..1000, got 100000" in str(r.exception)
    # the same limits wherever the setting is read (a pipeline's TOML builds the same configs)
    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.curation.classifier import ClassifierConfig

    with pytest.raises(ElicitError, match=r"classifier batch_size must be in 1\.\.65536"):
        ClassifierConfig(batch_size=10**8)
    with pytest.raises(ElicitError, match="classifier lr must be a number"):
        ClassifierConfig(lr=float("inf"))
    with pytest.raises(ElicitError, match=r"dropout samples must be in 0\.\.1000"):
        ScoreConfig.from_preset("square-nut", dropout_samples=1001)


def test_a_chunk_size_the_scorer_cannot_hold_is_one_line_and_writes_nothing(
    run, tmp_path, monkeypatch, capsys
):
    """``score --chunk-size`` 0 or beyond 65,536 pairs is refused in one line naming the flag
    and the range, with a non-zero exit and no output; the same limit holds wherever a chunk
    size is read (a pipeline's [score] section, a stored score config)."""
    from fixtures_data import run_cli

    from elicit_jax.compat.measures import (
        MAX_CHUNK_SIZE,
        ScoreConfig,
        config_dict,
        config_from_dict,
    )
    from elicit_jax.pipeline.stage_config import resolve_score

    for value in (10**8, 0):
        out = tmp_path / "out" / "s.parquet"
        out.parent.mkdir(exist_ok=True)
        code, _, err = run_cli(
            monkeypatch, capsys, "score", "--policy", run / "run", "--demos",
            run / "demos.parquet", "-o", out, "--preset", "square-nut", "--chunk-size", value,
        )  # fmt: skip
        lines = [line for line in err.splitlines() if line.strip()]
        assert code != 0 and len(lines) == 1, err
        assert f"--chunk-size) must be an integer in 1..65536, got {value}" in lines[0], err
        assert not any(out.parent.iterdir())
    assert ScoreConfig.from_preset("square-nut", chunk_size=MAX_CHUNK_SIZE).chunk_size == 65536
    stored = config_dict(ScoreConfig.from_preset("square-nut"))
    for bad in (MAX_CHUNK_SIZE + 1, 0, -1, "4096", 4096.0, True):
        with pytest.raises(ElicitError, match=r"chunk_size \(--chunk-size\) must be an integer"):
            ScoreConfig.from_preset("square-nut", chunk_size=bad)
        with pytest.raises(ElicitError, match=r"must be an integer in 1\.\.65536"):
            resolve_score({"task": "square-nut", "chunk_size": bad})
    with pytest.raises(ElicitError, match=r"must be an integer in 1\.\.65536, got 100000000"):
        config_from_dict({**stored, "chunk_size": 10**8}, "a stored config")


def test_many_dropout_passes_score_in_smaller_chunks_with_the_same_scores(run, monkeypatch):
    """Many passes shrink the compiled chunk (bounded memory); scores do not change beyond
    float32 rounding (another compiled shape)."""
    from elicit_jax.compat import score as score_mod
    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.compat.score import score_demos
    from elicit_jax.data.demos import read_demos
    from elicit_jax.policy.loaded import load_policy

    policy = load_policy(run / "run").policy
    demos = read_demos(run / "demos.parquet")
    config = ScoreConfig.from_preset("square-nut", dropout_samples=8, chunk_size=64)
    wide = score_demos(policy, demos, config)
    chunks = []
    real = score_mod.pad
    monkeypatch.setattr(score_mod, "MC_ROWS_BUDGET", 2 * 8 * 16)  # 2 members x 8 passes
    monkeypatch.setattr(score_mod, "pad", lambda x, n: chunks.append(n) or real(x, n))
    narrow = score_demos(policy, demos, config)
    assert chunks and max(chunks) <= 16
    np.testing.assert_allclose(wide["likelihood"], narrow["likelihood"], rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(wide["novelty"], narrow["novelty"], rtol=1e-5, atol=1e-7)


def test_a_policy_trained_on_absurd_observations_is_named_as_such(run, tmp_path):
    """A run an older elicit-jax trained on an obs of 1e30 (its std about 2e28): score says
    what is wrong with it, not "the checkpoint is corrupt"; info says so too."""
    import shutil

    shutil.copytree(run / "run", tmp_path / "run")
    norm = tmp_path / "run" / "seed0" / "normalization.npz"
    stats = dict(np.load(norm))
    stats["obs_std"] = stats["obs_std"].copy()
    stats["obs_std"][2] = 2e28
    with open(norm, "wb") as f:
        np.savez(f, **stats)
    out = tmp_path / "s.parquet"
    r = invoke("score", "--policy", tmp_path / "run", "--demos", run / "demos.parquet", "-o", out)
    msg = _one_line(r, norm, "obs_std[2] = 2e+28: the policy was trained on observations with "
                    "absurd values")  # fmt: skip
    assert "corrupt" not in msg and not out.exists()
    r = invoke("info", tmp_path / "run")
    assert "obs_std[2] = 2e+28" in " ".join(r.output.split()) and "check: ok" not in r.output
    # statistics that overflowed float32 say so
    stats["obs_std"][2] = np.inf
    with open(norm, "wb") as f:
        np.savez(f, **stats)
    r = invoke("score", "--policy", tmp_path / "run", "--demos", run / "demos.parquet", "-o", out)
    _one_line(r, norm, "statistics hold non-finite values (1 NaN/inf entries in 'obs_std'): the "
              "training data held values too large for float32")  # fmt: skip
