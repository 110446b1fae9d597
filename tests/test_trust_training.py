"""Thresholds checked against the base policy's own training demonstrations (issue #27, 3).

A real (tiny) base policy is trained on demos 0-9 of ``all.parquet`` (20 demos of operator
``base``, then 5 of ``other``); scores files are written by hand over those demos, recording
that policy and that demos file as ``score`` does, so that each demo's ℓ is known: "dirty"
demos have 3 of their 20 pairs (15% > the 5% rule) far off, the incompatible ones 6.
"""

import json
import shutil

import numpy as np
import pyarrow as pa
import pytest
from fixtures_data import invoke, tiny_episodes, tiny_train_config

from elicit_jax.artifact import make_header, write_parquet
from elicit_jax.compat.fit import FitJob, fit_scores_file
from elicit_jax.compat.measures import ScoreConfig, config_dict
from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.data.demos import from_episodes, read_demos, write_demos
from elicit_jax.errors import ElicitError
from elicit_jax.policy.train import train_policy

T = 20


@pytest.fixture(scope="module")
def d(tmp_path_factory):
    d = tmp_path_factory.mktemp("trust-training")
    demos = from_episodes(tiny_episodes(n=25, t=T), operators=["base"] * 20 + ["other"] * 5)
    write_demos(d / "all.parquet", demos)
    write_demos(d / "train.parquet", demos.select_episodes(range(10)))
    write_demos(d / "new.parquet", demos.select_episodes(range(10, 25)))
    train = read_demos(d / "train.parquet")
    train_policy(train, tiny_train_config(), d / "run", inputs={"demos": d / "train.parquet"})
    return d


def _scores(d, name, demos_file, dirty=(), incompatible=()):
    """A scores file over ``demos_file`` recording the policy ``d/run``: clean pairs have
    ℓ < 0.05, the first 3 pairs of a ``dirty`` demo and 6 of an ``incompatible`` one ℓ > 0.5,
    in familiar states (ν < 0.001, the others' ν < 0.01)."""
    rng = np.random.default_rng(0)
    demos = read_demos(d / demos_file)
    n = demos.n_steps
    ell, nu = rng.uniform(0.0, 0.05, n), rng.uniform(0.0, 0.01, n)
    for e, s, _ in demos.episode_bounds():
        k = 3 if e in dirty else 6 if e in incompatible else 0
        ell[s : s + k] = rng.uniform(0.5, 0.9, k)
        nu[s : s + k] = rng.uniform(0.0, 0.001, k)  # in familiar states
    table = pa.table(
        {
            "episode": pa.array(demos.episode.astype(np.int64)),
            "operator": pa.array(demos.operator.astype(str).tolist()),
            "step": pa.array(demos.step.astype(np.int32)),
            "likelihood": pa.array(ell.astype(np.float32)),
            "novelty": pa.array(nu.astype(np.float32)),
            "compatibility": pa.array(np.ones(n, np.float32)),
            "incompatible": pa.array(np.zeros(n, bool)),
        }
    )
    header = make_header(
        "scores",
        1,
        config=config_dict(ScoreConfig.from_preset("square-nut")),
        inputs={"demos": d / demos_file, "policy": d / "run"},
        policy={"which": "best", "seed": None},
        thresholds={"lambda": 0.4, "eta": 0.05},
    )
    write_parquet(d / name, table, header)
    return d / name


def _fit(scores, out, comp, inc, **kw):
    return fit_scores_file(scores, out, FitJob(comp, inc, **kw))


def test_one_operator_split_in_two_that_rejects_its_training_demos_is_refused(d, tmp_path):
    """The issue's case: a clean-looking fit on two halves of the base operator's own new
    demos rejects 6 of the 10 demos the policy was trained on."""
    s = _scores(d, "split.parquet", "all.parquet", dirty=range(6), incompatible=range(15, 20))
    out = tmp_path / "t.json"
    with pytest.raises(ElicitError, match=r"reject 6 of the base policy's 10 own training"):
        _fit(s, out, "episodes:10-14", "episodes:15-19")
    assert not out.exists()
    h = _fit(s, out, "episodes:10-14", "episodes:15-19", force=True)
    trust = json.loads(out.read_text())["report"]["trust"]
    assert trust["meaningless"] and trust["forced"] and trust["unchecked"] == []
    assert any(
        "both contrast sets are demonstrations of operator 'base'" in p for p in trust["problems"]
    )
    # the contrast checks alone found nothing: margin, held-out decisions, pairs all fine
    assert h["report"]["balanced_accuracy"] == 1.0 and h["report"]["margin_steps"] > 0
    assert h["report"]["training_check"] == {
        "demos": 10,
        "rejected": 6,
        "source": "10 scored in this file",
    }


def test_contrast_sets_inside_the_training_data_are_flagged(d, tmp_path):
    s = _scores(d, "clean.parquet", "all.parquet", incompatible=range(20, 25))
    h = _fit(s, tmp_path / "a.json", "episodes:6-9", "operator:other")
    trust = h["report"]["trust"]
    assert not trust["trustworthy"] and not trust["meaningless"]
    assert trust["problems"] == [
        "4 of the 4 demonstrations of the compatible set (episode 6, 7, 8, 9) are in the base "
        "policy's training data: the policy has fitted them, so their scores say nothing about "
        "new demonstrations"
    ]
    # held-out base demos against another operator: clean, every check run
    h = _fit(s, tmp_path / "b.json", "episodes:10-14", "operator:other")
    assert h["report"]["trust"]["problems"] == h["report"]["trust"]["unchecked"] == []
    # the base policy's training demos as the incompatible set: rejected, so refused
    s = _scores(d, "inc.parquet", "all.parquet", incompatible=[*range(5), *range(20, 25)])
    with pytest.raises(ElicitError, match=r"reject 5 of the base policy's 10"):
        _fit(s, tmp_path / "c.json", "episodes:10-14", "episodes:0-4")
    h = _fit(s, tmp_path / "c.json", "episodes:10-14", "episodes:0-4", force=True)
    text = " ".join(h["report"]["trust"]["problems"])
    assert "5 of the 5 demonstrations of the incompatible set (episode 0, 1, 2, 3, 4)" in text


def test_a_scorer_s_checks_name_the_training_demos_of_the_policy_that_scored(d, tmp_path):
    """With ``scorer`` (a pipeline's ``[scorer]`` scored), checks (a) and (c) say whose
    training demos they checked: the scoring policy's (D_base), not the base policy's."""
    s = _scores(d, "inc.parquet", "all.parquet", incompatible=[*range(5), *range(20, 25)])
    with pytest.raises(ElicitError) as refused:
        _fit(s, tmp_path / "c.json", "episodes:10-14", "episodes:0-4", scorer=True)
    assert "base policy" not in str(refused.value)
    assert "reject 5 of the 10 training demos of the policy that scored (D_base) (50%" in str(
        refused.value
    )
    h = _fit(s, tmp_path / "c.json", "episodes:10-14", "episodes:0-4", force=True, scorer=True)
    problems = h["report"]["trust"]["problems"]
    assert not any("base policy" in p for p in problems)
    assert (
        "5 of the 5 demonstrations of the incompatible set (episode 0, 1, 2, 3, 4) are in the "
        "training demos of the policy that scored (D_base): the policy has fitted them"
    ) in " ".join(problems)


def test_training_demos_not_in_the_scores_are_scored_under_the_policy(d, tmp_path):
    s = _scores(d, "new-scores.parquet", "new.parquet", incompatible=range(20, 25))
    src = f"10 scored now under {d / 'run' / 'seed0'}"
    # thresholds so low that every pair is incompatible: all 10 training demos rejected
    h = _fit(s, tmp_path / "low.json", None, None, manual=Thresholds(1e-9, 1e9, "given"))
    assert h["report"]["training_check"] == {"demos": 10, "rejected": 10, "source": src}
    assert "reject 10 of the base policy's 10 own training" in h["report"]["trust"]["severe"][0]
    h = _fit(s, tmp_path / "high.json", None, None, manual=Thresholds(1e9, 1e-9, "given"))
    assert h["report"]["training_check"]["rejected"] == 0
    # the training data file the checkpoint records is gone: said, and --base supplies it
    moved = tmp_path / "moved.parquet"
    shutil.move(d / "train.parquet", moved)
    try:
        h = _fit(s, tmp_path / "gone.json", None, None, manual=Thresholds(1e-9, 1e9, "given"))
        (note,) = [u for u in h["report"]["trust"]["unchecked"] if "training" in u]
        assert "10 of the 10 training demonstrations" in note and "is not there" in note
        assert "pass --base" in note
        h = _fit(
            s,
            tmp_path / "b.json",
            None,
            None,
            manual=Thresholds(1e-9, 1e9, "given"),
            base=(str(moved),),
        )
        assert h["report"]["training_check"]["rejected"] == 10
    finally:
        shutil.move(moved, d / "train.parquet")
    with pytest.raises(ElicitError, match=r"new.parquet: is not the data the base policy"):
        _fit(
            s,
            tmp_path / "w.json",
            None,
            None,
            manual=Thresholds(1e-9, 1e9, "given"),
            base=(d / "new.parquet",),
        )


def test_commands_that_load_thresholds_show_a_verdict_that_is_not_clean(d, tmp_path):
    s = _scores(d, "cli.parquet", "all.parquet", dirty=range(6), incompatible=range(15, 20))
    r = invoke(
        *("fit-thresholds", "--scores", s, "--compatible", "episodes:10-14"),
        *("--incompatible", "episodes:15-19", "-o", tmp_path / "t.json"),
    )
    assert r.exit_code == 1 and "reject 6 of the base policy's 10" in str(r.exception)
    r = invoke(
        *("fit-thresholds", "--scores", s, "--compatible", "episodes:10-14"),
        *("--incompatible", "episodes:15-19", "-o", tmp_path / "t.json", "--force"),
    )
    assert r.exit_code == 0 and "this fit is MEANINGLESS (written because of --force)" in r.output
    assert "6 / 10 (10 scored in this file)" in r.output
    shown = "t.json: judged when fitted: MEANINGLESS (written with --force): "
    (tmp_path / "inbox").mkdir()
    runs = {
        "score": ("score", "--policy", d / "run", "--demos", d / "new.parquet"),
        "filter": ("filter", "--scores", s, "--demos", d / "all.parquet"),
        "map": ("map", "--scores", s),
        "watch": ("watch", tmp_path / "inbox", "--policy", d / "run", "--base-demos",
                  d / "train.parquet", "--once", "--settle", "0"),
    }  # fmt: skip
    for cmd, args in runs.items():
        out = (
            ()
            if cmd == "watch"
            else ("-o", tmp_path / f"{cmd}.{'png' if cmd == 'map' else 'parquet'}")
        )
        r = invoke(*args, "--thresholds", tmp_path / "t.json", *out)
        assert r.exit_code == 0, (cmd, r.output)
        assert shown in r.output and "reject 6 of the base policy's 10" in r.output, cmd
    # a clean verdict is not repeated where the thresholds are used
    clean = _scores(d, "clean-cli.parquet", "all.parquet", incompatible=range(20, 25))
    r = invoke(
        *("fit-thresholds", "--scores", clean, "--compatible", "episodes:10-14"),
        *("--incompatible", "operator:other", "-o", tmp_path / "ok.json"),
    )
    assert "trust: no problems found" in r.output
    r = invoke(*runs["map"], "--thresholds", tmp_path / "ok.json", "-o", tmp_path / "m2.png")
    assert r.exit_code == 0 and "judged when fitted" not in r.output


def test_a_verdict_travels_with_the_thresholds():
    from elicit_jax.compat.trust import Verdict, thresholds_verdict

    v = Verdict(("p", "s"), ("s",), ("u",), forced=True)
    assert Verdict.from_dict(json.loads(json.dumps(v.to_dict()))) == v
    assert v.summary() == "MEANINGLESS (written with --force): p; s; not checked: u"
    # written before the training-data checks existed: said so, never taken as clean
    old = {"report": {"trust": {"trustworthy": True, "problems": [], "severe": []}}}
    assert not thresholds_verdict(old).clean
    assert "older elicit-jax" in thresholds_verdict(old).unchecked[0]
    assert not thresholds_verdict({"report": {}}).clean
