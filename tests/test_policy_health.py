"""A broken checkpoint is an error, never a score: NaN parameters, corrupt files, and what
``info`` says about them."""

import shutil

import jax
import numpy as np
import pytest
from fixtures_data import invoke, tiny_run

from elicit_jax.compat.measures import ScoreConfig
from elicit_jax.compat.score_file import score_file
from elicit_jax.errors import ElicitError
from elicit_jax.policy.base import init_policy
from elicit_jax.policy.checkpoint import flatten_params, load_params, unflatten_params


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return tiny_run(tmp_path_factory.mktemp("health"))


def _copy(run, tmp_path):
    shutil.copytree(run / "run", tmp_path / "run")
    return tmp_path / "run" / "seed0" / "params" / "best.npz"


def test_nan_parameters_are_an_error_naming_the_checkpoint(run, tmp_path):
    best = _copy(run, tmp_path)
    flat = flatten_params(load_params(best))
    flat = {k: np.full_like(v, np.nan) for k, v in flat.items()}
    with open(best, "wb") as f:
        np.savez(f, **flat)
    out = tmp_path / "scores.parquet"
    r = invoke("score", "--policy", tmp_path / "run", "--demos", run / "demos.parquet", "-o", out)
    assert isinstance(r.exception, ElicitError)
    assert "non-finite" in str(r.exception) and str(best) in str(r.exception)
    assert not out.exists()
    r = invoke("info", tmp_path / "run")
    assert r.exit_code == 0
    assert "check: 1 of 1 seeds have problems" in r.output and "non-finite" in r.output
    assert "check: ok" not in r.output


def test_nan_predictions_never_score_as_compatible(run, tmp_path):
    """The scorer's own guard, for a policy that reaches it with NaN weights."""
    policy = init_policy(
        jax.random.key(0), kind="mlp", obs_dim=3, action_dim=2, n_members=2, hidden=(8,)
    )
    nan = unflatten_params(
        {k: np.full(v.shape, np.nan, np.float32) for k, v in flatten_params(policy.params).items()}
    )
    policy = policy.replace(params=jax.tree.map(jax.numpy.asarray, nan))
    out = tmp_path / "s.parquet"
    with pytest.raises(ElicitError, match=r"not finite.*episode 0, step 0"):
        score_file(policy, run / "demos.parquet", out, ScoreConfig.from_preset("square-nut"))
    assert not out.exists()


def test_a_corrupt_parameter_file_is_one_line(run, tmp_path):
    best = _copy(run, tmp_path)
    best.write_bytes(b"PK\x03\x04 not really a zip archive")
    r = invoke(
        "score", "--policy", tmp_path / "run", "--demos", run / "demos.parquet", "-o",
        tmp_path / "s.parquet",
    )  # fmt: skip
    assert isinstance(r.exception, ElicitError)
    assert "unreadable parameter file" in str(r.exception) and "\n" not in str(r.exception)
    r = invoke("info", tmp_path / "run")
    assert "unreadable parameter file" in r.output and "check: ok" not in r.output


def test_a_healthy_run_says_so(run):
    r = invoke("info", run / "run")
    assert r.exit_code == 0 and "check: ok" in r.output
