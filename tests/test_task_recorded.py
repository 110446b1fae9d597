"""A policy runs on the task it was trained on (issue #45, item 17): every simulated task takes
23 observations and 7 actions, so `evaluate` on the wrong one reported 0% without a word.
`evaluate`, `elicit` and `serve` default to the recorded task and refuse another without
--force (robosuite tasks too)."""

import numpy as np
import pandas as pd
import pytest
from fixtures_data import invoke, tiny_train_config

from elicit_jax.artifact import make_header, read_header, write_json
from elicit_jax.errors import ElicitError


@pytest.fixture(scope="module")
def reach(tmp_path_factory):
    """A tiny policy trained on 3 collected reach-pillar demos."""
    from elicit_jax.data.demos import read_demos
    from elicit_jax.policy.train import train_policy

    d = tmp_path_factory.mktemp("task")
    r = invoke("collect", "--task", "reach-pillar", "--operator", "base", "--episodes", "3",
               "-o", d / "base.parquet")  # fmt: skip
    assert r.exit_code == 0, r.output
    train_policy(read_demos(d / "base.parquet"), tiny_train_config(), d / "run", quiet=True)
    return d


def _evaluate(reach, out, *extra):
    return invoke("evaluate", "--policy", reach / "run", "--rollouts", "2", "--horizon", "5",
                  "--backend", "mujoco", "-o", out, *extra)  # fmt: skip


def test_evaluate_runs_the_recorded_task_and_refuses_another(reach, tmp_path):
    out = tmp_path / "e.parquet"
    r = _evaluate(reach, out)
    assert r.exit_code == 0, (r.output, r.exception)
    assert "task: reach-pillar (recorded by the policies' training run)" in r.output
    assert read_header(out)["task"] == "reach-pillar"
    # another task: refused, nothing written
    wrong = tmp_path / "wrong.parquet"
    r = _evaluate(reach, wrong, "--task", "square-nut")
    assert isinstance(r.exception, ElicitError), r.output
    msg = str(r.exception)
    assert msg.startswith(f"{reach / 'run'}: records task 'reach-pillar', not 'square-nut'")
    assert "pass --force" in msg and not wrong.exists()
    # forced: it runs, and says so
    r = _evaluate(reach, wrong, "--task", "square-nut", "--force")
    assert r.exit_code == 0, (r.output, r.exception)
    assert "--force: running on 'square-nut' anyway" in " ".join(r.output.split())
    assert read_header(wrong)["task"] == "square-nut"
    assert len(pd.read_parquet(wrong)) == 2
    from elicit_jax.sim.task_match import recorded_task

    assert recorded_task(reach / "run") == "reach-pillar"
    assert recorded_task(reach / "run" / "seed0") == "reach-pillar"  # from its run


def _run_recording(tmp_path, name, task):
    d = tmp_path / name
    d.mkdir()
    write_json(d / "artifact.json", make_header("training_run", 1, task=task))
    return d


def test_robosuite_tasks_and_imported_environment_names(tmp_path):
    square = _run_recording(tmp_path, "rs", "robosuite-square")
    r = invoke("evaluate", "--policy", square, "--task", "square-nut", "--rollouts", "1")
    assert isinstance(r.exception, ElicitError)
    assert "records task 'robosuite-square', not 'square-nut'" in str(r.exception)
    from elicit_jax.sim.task_match import resolve_task

    assert resolve_task(None, [square]) == ("robosuite-square", [])
    # a robomimic import records robosuite's environment name: both square tasks play it
    imported = _run_recording(tmp_path, "rm", "NutAssemblySquare")
    with pytest.raises(ElicitError, match="any of robosuite-square, square-nut plays; pass --task"):
        resolve_task(None, [imported])
    assert resolve_task("robosuite-square", [imported]) == ("robosuite-square", [])
    with pytest.raises(
        ElicitError, match="records task 'NutAssemblySquare', not 'robosuite-round'"
    ):
        resolve_task("robosuite-round", [imported])
    task, notes = resolve_task("robosuite-round", [imported], force=True)
    assert task == "robosuite-round" and "--force" in notes[0]
    # nothing recorded: --task is needed, and any is taken
    unknown = _run_recording(tmp_path, "un", "unknown")
    with pytest.raises(ElicitError, match="records no task"):
        resolve_task(None, [unknown])
    assert resolve_task("square-nut", [unknown]) == ("square-nut", [])
    # inputs that disagree
    with pytest.raises(ElicitError, match="record different tasks"):
        resolve_task(None, [square, _run_recording(tmp_path, "rp", "reach-pillar")])


@pytest.mark.parametrize("command", ["elicit", "serve"])
def test_sessions_refuse_a_task_the_policy_was_not_trained_on(reach, tmp_path, command):
    args = [command, "--task", "square-nut", "--policy", reach / "run",
            "--base-demos", reach / "base.parquet", "--lambda", "0.4", "--eta", "0.05"]  # fmt: skip
    if command == "elicit":
        args += ["--operator", "scripted:base", "-o", tmp_path / "s"]
    else:
        args += ["--sessions", tmp_path / "s", "--port", "0"]
    r = invoke(*args)
    assert isinstance(r.exception, ElicitError), r.output
    assert "records task 'reach-pillar', not 'square-nut'" in str(r.exception)
    assert not (tmp_path / "s").exists()


def test_sessions_default_to_the_recorded_task(reach):
    from elicit_jax.cli.session_options import recorded_task as session_task

    given = {"policy": str(reach / "run"), "base_demos": str(reach / "base.parquet")}
    session_task(given, force=False)
    assert given["task"] == "reach-pillar"


def test_watch_refuses_demonstrations_of_another_task(tmp_path):
    """A square-nut policy judging an inbox file recorded on NutAssemblyRound: an error line
    naming the file; `--task` (the import's task override) names the demos' task."""
    from fixtures_data import tiny_episodes, write_robomimic

    from elicit_jax.compat.threshold_source import Thresholds
    from elicit_jax.data.demos import from_episodes, write_demos
    from elicit_jax.elicit.watch import WatchConfig, Watcher
    from elicit_jax.policy.train import train_policy

    demos = from_episodes(tiny_episodes(), operators="base", task="square-nut")
    write_demos(tmp_path / "base.parquet", demos)
    train_policy(demos, tiny_train_config(), tmp_path / "run", quiet=True)
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    ep = tiny_episodes(n=1, seed=5)[0]
    demo = {"actions": ep["action"], "obs/a": ep["obs"], "rewards": np.r_[np.zeros(19), 1]}
    item = write_robomimic(inbox / "round.hdf5", {"demo_0": demo}, env_name="NutAssemblyRound")

    def judge(**options):
        lines = []
        config = WatchConfig(
            inbox=str(inbox),
            policy=str(tmp_path / "run"),
            base_demos=str(tmp_path / "base.parquet"),
            thresholds=Thresholds(0.4, 0.05, "given"),
            import_options=(("obs_keys", ("a",)), *options.items()),
            settle=0.0,
        )
        Watcher(config, echo=lines.append).scan(now=1e9)
        return lines

    (line,) = judge()
    assert line.startswith(f"error: {item}: holds demonstrations of task 'NutAssemblyRound', "
                           "but the policy")  # fmt: skip
    assert "trained on 'square-nut'" in line
    lines = judge(task="square-nut")
    assert len(lines) == 1 and lines[0].startswith("round.hdf5 / demo_0: "), lines
