"""End to end through the CLI: train a tiny base policy, score, fit, filter, map, info."""

import json

import numpy as np
import pytest
from fixtures_data import cli_ok, invoke

from elicit_jax.compat.score_file import read_scores
from elicit_jax.data.demos import from_episodes, read_demos, write_demos
from elicit_jax.errors import ElicitError


def _operator(rng, n, style, length=30):
    """1-D reach toward 0: the base style moves proportionally (a = -0.5 x); the 'bad'
    operator pushes the other way in the same states (a = +0.5 x)."""
    eps = []
    for _ in range(n):
        x = rng.uniform(-1, 1, size=(length, 2)).astype(np.float32)
        a = (-0.5 if style == "base" else 0.5) * x
        eps.append({"obs": x, "action": a.astype(np.float32)})
    return eps


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from elicit_jax.policy.config import TrainConfig
    from elicit_jax.policy.train import train_policy

    d = tmp_path_factory.mktemp("cli")
    rng = np.random.default_rng(0)
    base = from_episodes(_operator(rng, 12, "base"), operators="base")
    write_demos(d / "base.parquet", base)
    new_eps = _operator(rng, 4, "base") + _operator(rng, 4, "bad")
    new = from_episodes(new_eps, operators=["good"] * 4 + ["bad"] * 4)
    write_demos(d / "new.parquet", new)
    cfg = TrainConfig(
        ensemble_size=3,
        hidden=(32, 32),
        dropout=0.0,
        epochs=60,
        batch_size=64,
        checkpoint_every=60,
        progress_every=20,
        seeds=(0,),
        val_fraction=0.2,
    )
    train_policy(base, cfg, d / "runs", quiet=True)
    return d


def test_score_fit_filter_map(run):
    d = run
    cli_ok(
        "score",
        "--policy",
        str(d / "runs"),
        "--demos",
        str(d / "new.parquet"),
        "-o",
        str(d / "scores.parquet"),
        "--lambda",
        "0.05",
        "--eta",
        "0.5",
        "--chunk-size",
        "64",
    )
    header, s = read_scores(d / "scores.parquet")
    assert header["thresholds"] == {"lambda": 0.05, "eta": 0.5}
    assert "policy" in header["inputs"]
    assert header["policy"]["which"] == "best" and header["policy"]["seed"] is None
    assert len(header["policy"]["policy_sha256"]) == 64  # what the policy computes with
    ops = s["operator"].astype(str)
    # the policy learned the base mapping: the opposite-style operator has far larger errors
    assert s["likelihood"][ops == "bad"].mean() > 5 * s["likelihood"][ops == "good"].mean()

    r = cli_ok(
        "fit-thresholds",
        "--scores",
        str(d / "scores.parquet"),
        "--compatible",
        "operator:good",
        "--incompatible",
        "operator:bad",
        "-o",
        str(d / "t.json"),
    )
    assert "balanced accuracy" in r.output
    t = json.loads((d / "t.json").read_text())
    assert t["kind"] == "thresholds" and t["method"] == "fit"
    assert t["report"]["balanced_accuracy"] == 1.0
    assert t["report"]["per_operator"]["bad"]["rejected_episodes"] == 4
    assert t["report"]["per_operator"]["good"]["rejected_episodes"] == 0

    cli_ok(
        "filter",
        "--scores",
        str(d / "scores.parquet"),
        "--demos",
        str(d / "new.parquet"),
        "--base",
        str(d / "base.parquet"),
        "-o",
        str(d / "f.parquet"),
        "--level",
        "episode",
        "--thresholds",
        str(d / "t.json"),
    )
    f = read_demos(d / "f.parquet")
    assert sorted(set(f.operator.astype(str))) == ["base", "good"]

    for name in ("map.png", "map.html"):
        cli_ok(
            "map",
            "--scores",
            str(d / "scores.parquet"),
            "-o",
            str(d / name),
            "--thresholds",
            str(d / "t.json"),
        )
        assert (d / name).stat().st_size > 1000
    for artifact in ("scores.parquet", "scores.episodes.parquet", "t.json", "f.dropped.parquet"):
        cli_ok("info", str(d / artifact))


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--lambda", "0.1"], "--lambda and --eta go together"),
        (["--preset", "peg"], "unknown preset"),
    ],
)
def test_cli_errors_are_clear(run, flags, message):
    d = run
    args = ["score", "--policy", d / "runs", "--demos", d / "new.parquet", "-o", d / "x.parquet"]
    result = invoke(*args, *flags)
    assert isinstance(result.exception, ElicitError)
    assert message in str(result.exception)
