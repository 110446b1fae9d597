"""The one policy loader (issue #48, item 4): a checkpoint read once into a typed
``LoadedPolicy``; a checkpoint without a model kind, or of sizes the task does not give and
take, is refused with one line naming the file; ``score``, ``evaluate``, the session set-up and
``watch`` load through it (each refuses the planted checkpoint with the loader's words)."""

from __future__ import annotations

import json
import shutil

import pytest
from fixtures_data import invoke, tiny_run

from elicit_jax.artifact import read_header
from elicit_jax.errors import ElicitError
from elicit_jax.policy.base import Policy
from elicit_jax.policy.kinds import model_kind
from elicit_jax.policy.loaded import LoadedPolicy, load_policy, policy_sha256
from elicit_jax.sim.registry import ACTION_DIM, OBS_DIM, task_entry

NO_KIND = "checkpoint records no model kind"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A tiny run (obs 3, action 2: no simulated task's sizes) and its demos."""
    return tiny_run(tmp_path_factory.mktemp("loader"))


def _planted(run, tmp_path, change):
    """A copy of the run whose seed header ``change`` altered; returns (run copy, header)."""
    copy = tmp_path / "planted"
    shutil.copytree(run / "run", copy)
    header_file = copy / "seed0" / "artifact.json"
    header = json.loads(header_file.read_text())
    change(header)
    header_file.write_text(json.dumps(header))
    return copy, header_file


def _no_kind(header):
    del header["model"]["kind"]


def _one_line(e, path, text):
    msg = str(e.value) if hasattr(e, "value") else str(e)
    assert msg.startswith(f"{path}: ") and text in msg and "\n" not in msg, msg


def test_the_loader_returns_a_typed_loaded_policy(run):
    loaded = load_policy(run / "run")
    assert isinstance(loaded, LoadedPolicy) and isinstance(loaded.policy, Policy)
    assert loaded.kind is model_kind("mlp") and (loaded.obs_dim, loaded.action_dim) == (3, 2)
    assert loaded.task is None  # the tiny demos record no task
    norm = loaded.normalization
    assert set(norm) == {"obs_mean", "obs_std", "action_std"} and norm["obs_mean"].shape == (3,)
    # the hash thresholds bind to: what the policy computes with, however its path was given
    again = load_policy(run / "run" / "seed0", "best")
    assert loaded.sha256 == again.sha256 == policy_sha256(loaded.policy)


def test_a_checkpoint_without_a_model_kind_is_refused_naming_its_file(run, tmp_path):
    copy, header_file = _planted(run, tmp_path, _no_kind)
    with pytest.raises(ElicitError) as e:
        load_policy(copy)
    _one_line(e, header_file, NO_KIND)
    copy2, header_file2 = _planted(run, tmp_path / "b", lambda h: h.pop("model"))
    with pytest.raises(ElicitError) as e:
        load_policy(copy2)
    _one_line(e, header_file2, NO_KIND)


def test_info_names_a_checkpoint_without_a_model_kind(run, tmp_path):
    copy, header_file = _planted(run, tmp_path, _no_kind)
    r = invoke("info", copy / "seed0")
    assert isinstance(r.exception, ElicitError), r.output
    _one_line(r.exception, header_file, NO_KIND)


def test_a_checkpoint_of_other_sizes_than_the_task_is_refused(run):
    sizes = task_entry("reach-pillar")
    assert (sizes.obs_dim, sizes.action_dim) == (OBS_DIM, ACTION_DIM) == (23, 7)
    with pytest.raises(ElicitError) as e:
        load_policy(run / "run", task=sizes)
    _one_line(
        e,
        run / "run",
        "policy has obs_dim=3, action_dim=2; task 'reach-pillar' needs obs_dim=23, action_dim=7",
    )


def test_the_recorded_task_comes_with_the_policy(run, tmp_path):
    copy, _ = _planted(run, tmp_path, lambda h: h.update(task="round-nut"))
    assert load_policy(copy).task == "round-nut"
    assert read_header(copy / "seed0")["task"] == "round-nut"
    # what --task defaults to is read the same way, from the headers alone (no parameters)
    from elicit_jax.sim.task_match import recorded_task

    for f in (copy / "seed0" / "params").iterdir():
        f.unlink()
    assert recorded_task(copy / "seed0") == "round-nut"


def test_score_loads_through_the_loader(run, tmp_path):
    copy, header_file = _planted(run, tmp_path, _no_kind)
    out = tmp_path / "s.parquet"
    args = ("--demos", run / "demos.parquet", "-o", out, "--lambda", "0.4", "--eta", "0.05")
    r = invoke("score", "--policy", copy, *args)
    assert isinstance(r.exception, ElicitError), r.output
    _one_line(r.exception, header_file, NO_KIND)
    assert not out.exists()


def test_evaluate_loads_through_the_loader(run, tmp_path):
    out = tmp_path / "e.parquet"
    args = ("--task", "reach-pillar", "--rollouts", "1", "--backend", "mujoco", "-o", out)
    r = invoke("evaluate", "--policy", run / "run", *args)
    assert isinstance(r.exception, ElicitError), r.output
    # evaluate expands a run into its seed directories: the seed's is named
    seed0 = run / "run" / "seed0"
    _one_line(r.exception, seed0, "task 'reach-pillar' needs obs_dim=23, action_dim=7")
    copy, header_file = _planted(run, tmp_path, _no_kind)
    r = invoke("evaluate", "--policy", copy, *args)
    _one_line(r.exception, header_file, NO_KIND)
    assert not out.exists()


def test_session_and_watch_set_up_load_through_the_loader(run, tmp_path):
    from elicit_jax.compat.thresholds import Thresholds
    from elicit_jax.data.demos import read_demos
    from elicit_jax.elicit.inputs import load_session_policy
    from elicit_jax.elicit.watch import WatchConfig, Watcher

    base_path = run / "demos.parquet"
    base = read_demos(base_path)
    loaded = load_session_policy(run / "run", "best", None, base, base_path)
    assert isinstance(loaded, LoadedPolicy) and loaded.sha256 == load_policy(run / "run").sha256
    with pytest.raises(ElicitError) as e:  # a session on a task: the task's sizes
        load_session_policy(run / "run", "best", None, base, base_path, task="reach-pillar")
    _one_line(e, run / "run", "task 'reach-pillar' needs obs_dim=23")
    copy, header_file = _planted(run, tmp_path, _no_kind)
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    config = WatchConfig(
        inbox=str(inbox),
        policy=str(copy),
        base_demos=str(base_path),
        thresholds=Thresholds(0.4, 0.05, "given"),
    )
    with pytest.raises(ElicitError) as e:
        Watcher(config, echo=lambda _: None)
    _one_line(e, header_file, NO_KIND)
