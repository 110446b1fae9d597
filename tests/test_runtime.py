"""XLA's CPU thread count per workload: one thread per CPU, at least 4 where MJX runs."""

import os

import numpy as np
import pytest

from elicit_jax import runtime
from elicit_jax.cli.app import _steps_mjx
from elicit_jax.errors import ElicitError


def test_threads_per_workload(monkeypatch):
    monkeypatch.setattr(runtime, "available_cpus", lambda: 2)
    assert runtime.cpu_threads() == 2
    assert runtime.cpu_threads(mjx=True) == runtime.MJX_MIN_THREADS == 4
    monkeypatch.setattr(runtime, "available_cpus", lambda: 16)
    assert runtime.cpu_threads(mjx=True) == 16


def test_configure_sizes_the_pool_and_keeps_a_user_setting(monkeypatch):
    monkeypatch.setattr(runtime, "available_cpus", lambda: 2)
    monkeypatch.delenv("PJRT_NPROC", raising=False)
    monkeypatch.delenv(runtime.THREADS_OWNER_ENV, raising=False)
    runtime.configure()
    assert os.environ["PJRT_NPROC"] == "2"
    monkeypatch.delenv("PJRT_NPROC")
    runtime.configure(mjx=True)
    assert os.environ["PJRT_NPROC"] == "4"
    monkeypatch.setenv("PJRT_NPROC", "3")
    runtime.configure(mjx=True)
    assert os.environ["PJRT_NPROC"] == "3"


def test_a_child_given_fewer_cpus_resizes_an_inherited_default_only(monkeypatch):
    """A Ray task holding 1 CPU of 2 inherits its driver's PJRT_NPROC=2: sized anew to 1 when
    elicit-jax chose the 2, kept when the user did."""
    monkeypatch.setattr(runtime, "available_cpus", lambda: 2)
    monkeypatch.delenv("PJRT_NPROC", raising=False)
    monkeypatch.delenv(runtime.THREADS_OWNER_ENV, raising=False)
    runtime.configure()  # the driver
    assert (os.environ["PJRT_NPROC"], os.environ[runtime.THREADS_OWNER_ENV]) == ("2", "1")
    runtime.configure()  # a child told nothing more keeps it
    assert os.environ["PJRT_NPROC"] == "2"
    runtime.configure(cpus=1)  # a one-CPU task
    assert os.environ["PJRT_NPROC"] == "1"
    runtime.configure(mjx=True, cpus=1)
    assert os.environ["PJRT_NPROC"] == "4"
    monkeypatch.delenv(runtime.THREADS_OWNER_ENV)
    monkeypatch.setenv("PJRT_NPROC", "3")  # the user's
    runtime.configure(cpus=1)
    assert os.environ["PJRT_NPROC"] == "3" and runtime.THREADS_OWNER_ENV not in os.environ


def test_mjx_refuses_a_pool_that_deadlocks_it(monkeypatch):
    monkeypatch.setenv("PJRT_NPROC", "2")
    with pytest.raises(ElicitError, match="PJRT_NPROC=4"):
        runtime.check_mjx_threads()
    monkeypatch.setenv("PJRT_NPROC", "4")
    runtime.check_mjx_threads()


@pytest.mark.parametrize(
    ("argv", "mjx"),
    [
        (["evaluate", "p", "--backend", "mjx"], True),
        (["evaluate", "p", "--backend=mjx"], True),
        (["evaluate", "p", "--backend", "mujoco"], False),
        (["score", "p", "d", "--out", "mjx"], False),
        (["train", "--backend"], False),
    ],
)
def test_cli_sizes_the_pool_for_mjx_only_when_asked(argv, mjx):
    assert _steps_mjx(argv) is mjx


def test_cli_sizes_the_pool_for_a_definition_that_evaluates_with_mjx(tmp_path):
    mjx = tmp_path / "mjx.toml"
    mjx.write_text('[pipeline]\nname = "x"\n[tasks.square-nut.evaluate]\nbackend = "mjx"\n')
    c = tmp_path / "c.toml"
    c.write_text('[pipeline]\nname = "x"\n[evaluate]\nbackend = "mujoco"\n')
    assert _steps_mjx(["pipeline", "run", str(mjx), "--profile", "cpu"]) is True
    assert _steps_mjx(["--debug", "pipeline", "run", "--out", "o", str(mjx)]) is True
    assert _steps_mjx(["pipeline", "run", str(c)]) is False
    assert _steps_mjx(["pipeline", "run", str(tmp_path / "missing.toml")]) is False
    assert _steps_mjx(["pipeline", "status", str(mjx)]) is False
    assert _steps_mjx(["pipeline", "run", "quickstart"]) is False


def test_tables_are_not_cut_at_80_columns_in_a_file_or_pipe(tmp_path):
    """`demos list x | cat` cut a wide table at 80 columns ("axis_operat…"); the CLI widens
    the console when stdout is not a terminal, unless COLUMNS says otherwise."""
    import subprocess
    import sys

    from elicit_jax.data.demos import from_episodes, write_demos

    rng = np.random.default_rng(0)
    eps = [{"obs": rng.normal(size=(3, 2)), "action": rng.uniform(-1, 1, (3, 2))} for _ in range(2)]
    name = "a_proficient_operator_with_a_rather_long_name_from_a_real_lab"
    write_demos(tmp_path / "d.parquet", from_episodes(eps, operators=name))
    env = {k: v for k, v in os.environ.items() if k != "COLUMNS"}
    code = "from elicit_jax.cli import main; main()"

    def listing(**extra):
        args = [sys.executable, "-c", code, "demos", "list", str(tmp_path / "d.parquet")]
        run = subprocess.run(args, capture_output=True, text=True, env={**env, **extra})
        assert run.returncode == 0, run.stderr
        return run.stdout

    assert name in listing()
    assert name not in listing(COLUMNS="80")  # the user's own width is kept


def test_configure_console_leaves_a_terminal_and_a_user_width_alone(monkeypatch):
    import io
    import sys

    for name in ("COLUMNS", runtime.WIDE_OWNER_ENV):  # recorded, so that both are restored
        monkeypatch.setenv(name, "")
        monkeypatch.delenv(name)
    monkeypatch.setattr(sys, "stdout", io.StringIO())
    runtime.configure_console()
    assert os.environ["COLUMNS"] == str(runtime.WIDE_CONSOLE)
    monkeypatch.setenv("COLUMNS", "100")
    runtime.configure_console()
    assert os.environ["COLUMNS"] == "100"
    assert runtime.stderr_width() is None or runtime.stderr_width() > 0


def test_mjx_imports_without_the_stray_warp_line():
    """mujoco.mjx prints "Failed to import warp: ..." on stdout when Warp is absent (it is
    never used); the one import elicit-jax makes keeps it off the user's screen."""
    import subprocess
    import sys

    code = "from elicit_jax.sim.env import import_mjx; print(import_mjx().__name__)"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "mujoco.mjx"
    assert "warp" not in (run.stdout + run.stderr).lower()


def test_mjx_progress_bar_says_it_is_compiling(monkeypatch):
    """The MJX bar sat at 0% through a cold compile with nothing said; it now says
    "compiling…" until the first policy is done, then what it counts."""
    import rich.progress

    from elicit_jax.cli import sim_cmds
    from elicit_jax.sim import evaluate
    from elicit_jax.sim.evaluate import EvalConfig

    seen = []

    def add_task(self, description, **kw):
        seen.append(description)
        return rich.progress.TaskID(0)

    def update(self, task_id, **kw):
        seen.append(kw.get("description"))

    def fake_eval(policy, config, out, progress, trajectories):
        progress("run", 1.0)
        return None, "summary"

    monkeypatch.setattr(rich.progress.Progress, "add_task", add_task)
    monkeypatch.setattr(rich.progress.Progress, "update", update)
    monkeypatch.setattr(evaluate, "expand_policies", lambda p, c: ["run"])
    monkeypatch.setattr(evaluate, "resolve_backend", lambda *a: "mjx")
    monkeypatch.setattr(evaluate, "evaluate_policies", fake_eval)
    config = EvalConfig(task="reach-pillar", rollouts=2, backend="mjx")
    n, _ = sim_cmds._evaluate_with_bar(["run"], config, None, None, "reach-pillar")
    assert n == 1
    assert "compiling…" in seen[0] and seen[1] == "reach-pillar: 1 policies x 2 rollouts"


def test_the_robosuite_extra_resolves_once_and_needs_no_compiler():
    """`pip install -e '.[robosuite]'` downloaded robosuite 1.5.2, backtracked to 1.5.1 (1.5.2's
    mink pin needs numpy<2), and compiled evdev from source (pynput >= 1.7 needs it on
    Linux; it has no wheels): the extra pins the version pip ends on, and a pynput without
    evdev (robosuite uses it only for its keyboard device)."""
    import tomllib
    from pathlib import Path

    from packaging.requirements import Requirement

    project = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
    extra = {
        r.name: r
        for r in map(Requirement, project["project"]["optional-dependencies"]["robosuite"])
    }
    assert str(extra["robosuite"].specifier) == "==1.5.1"
    pynput = extra["pynput"].specifier
    assert "1.6.8" in pynput and "1.7.0" not in pynput and "1.8.2" not in pynput


def test_headers_name_what_makes_numbers_machine_specific():
    """Results are bit-identical only on the same CPU model with the same XLA thread count
    (docs/outputs.md, "Across machines"): every header records both, so a user comparing with
    a committed report can tell whether the digits should match."""
    from pathlib import Path

    from elicit_jax.artifact import make_header
    from elicit_jax.provenance import ISA_LEVELS

    settings = make_header("demos", 1)["runtime"]
    assert {"cpu", "cpu_isa", "cpus", "PJRT_NPROC", "XLA_FLAGS"} <= set(settings)
    assert settings["cpu"] and settings["cpu_isa"] in (*ISA_LEVELS, "unknown")
    doc = (Path(__file__).resolve().parents[1] / "docs" / "outputs.md").read_text()
    assert "## Across machines" in doc and "`cpu_isa`" in doc and "PJRT_NPROC" in doc
