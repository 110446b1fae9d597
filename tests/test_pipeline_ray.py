"""The Ray executor on Ray's local cluster: a small grid of cheap test-local stages.

The fake stages live in this module; it is registered with Ray's cloudpickle *by value*, so the
worker processes get the functions without importing this test file.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from rich.console import Console

from elicit_jax.artifact import make_header, read_json, write_json
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.graph import Graph, Stage
from elicit_jax.pipeline.runner import StageContext, record_path, run_graph
from elicit_jax.runtime import THREADS_OWNER_ENV

ray = pytest.importorskip("ray")
# Ray forks-and-execs its own processes from a driver that may already have imported JAX.
pytestmark = pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")

from elicit_jax.pipeline.ray_runner import import_ray, run_graph_ray  # noqa: E402

TASKS, OPERATORS, SEEDS = ("t0", "t1"), ("op0", "op1"), (0, 1)


def add_stage(ctx: StageContext) -> None:
    """Output value = config 'value' + the input artifacts' values; records the worker's pid."""
    total = int(ctx.config.get("value", 0))
    for path in ctx.inputs.values():
        total += read_json(path)["value"]
    header = make_header("test-add", 1, config=dict(ctx.config), inputs=dict(ctx.inputs))
    header.update(value=total, pid=os.getpid(), xla_flags=os.environ.get("XLA_FLAGS", ""),
                  pjrt_nproc=os.environ.get("PJRT_NPROC"))  # fmt: skip
    write_json(ctx.output, header)


def crash_on_t1_op1_s1(ctx: StageContext) -> None:
    if ctx.stage.id == "train/t1/op1/s1":
        raise RuntimeError("simulated crash")
    add_stage(ctx)


def grid(bump: int = 0) -> Graph:
    """collect per task -> train per task × operator × seed -> evaluate each -> one report;
    ``bump`` is added to the config value of the train cell t0/op1/s0."""
    stages = []
    for ti, t in enumerate(TASKS):
        stages.append(Stage(f"collect/{t}", "add", f"data/{t}.json", {"value": 100 * (ti + 1)}))
        for oi, op in enumerate(OPERATORS):
            for s in SEEDS:
                cell = f"{t}/{op}/s{s}"
                cfg = {"value": 10 * oi + s + bump * (cell == "t0/op1/s0")}
                stages.append(
                    Stage(
                        f"train/{cell}", "add", f"policies/{cell}.json", cfg, {"d": f"collect/{t}"}
                    )
                )
                stages.append(
                    Stage(
                        f"evaluate/{cell}", "add", f"evals/{cell}.json", {}, {"p": f"train/{cell}"}
                    )
                )
    evals = {s.id: s.id for s in stages if s.kind == "add" and s.id.startswith("evaluate/")}
    stages.append(Stage("report", "add", "report.json", {}, evals))
    return Graph(stages)


def quiet() -> Console:
    return Console(quiet=True)


@pytest.fixture(scope="module")
def cluster():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    yield
    ray.cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    ray.shutdown()


def values(run_dir: Path, graph: Graph) -> dict[str, int]:
    return {s.id: read_json(run_dir / s.output)["value"] for s in graph}


def test_grid_on_ray_matches_local_executor_and_second_run_skips(cluster, tmp_path):
    graph = grid()
    result = run_graph_ray(graph, tmp_path / "ray", {"add": add_stage}, console=quiet())
    assert sorted(result.ran) == sorted(s.id for s in graph) and not result.skipped
    local = run_graph(graph, tmp_path / "local", {"add": add_stage}, console=quiet())
    assert sorted(local.ran) == sorted(result.ran)
    got = values(tmp_path / "ray", graph)
    assert got == values(tmp_path / "local", graph)
    # t1/op1/s1: collect 200, train 200 + 10*1 + 1 = 211, evaluate 211
    assert got["evaluate/t1/op1/s1"] == 211
    # report = sum over tasks (100, 200) × 4 cells of collect + sum of (0, 1, 10, 11) per task
    #        = 4 * 100 + 22 + 4 * 200 + 22 = 1244
    assert got["report"] == 1244
    out = read_json(tmp_path / "ray" / "report.json")
    assert out["kind"] == "test-add" and "schema_version" in out
    assert out["pid"] != os.getpid()  # the work happened in a Ray worker process
    assert "--xla_cpu_use_fusion_emitters=false" in out["xla_flags"]  # runtime configured
    # each task holds 1 CPU: XLA's pool is sized to it, unless the user set PJRT_NPROC
    ours = os.environ.get(THREADS_OWNER_ENV) == "1"
    assert out["pjrt_nproc"] == ("1" if ours else os.environ.get("PJRT_NPROC"))
    assert record_path(tmp_path / "ray", graph["report"]).exists()
    assert not list((tmp_path / "ray").rglob(".*.tmp"))

    again = run_graph_ray(graph, tmp_path / "ray", {"add": add_stage}, console=quiet())
    assert again.ran == [] and again.skipped == [s.id for s in graph]


def test_changed_cell_config_reruns_only_that_cell_and_downstream(cluster, tmp_path):
    run_graph_ray(grid(), tmp_path, {"add": add_stage}, console=quiet())
    result = run_graph_ray(grid(bump=40), tmp_path, {"add": add_stage}, console=quiet())
    assert result.ran == ["train/t0/op1/s0", "evaluate/t0/op1/s0", "report"]
    assert len(result.skipped) == len(grid()) - 3
    assert values(tmp_path, grid())["report"] == 1244 + 40


def test_failing_stage_is_one_line_error_naming_it_and_run_resumes(cluster, tmp_path):
    graph = grid()
    with pytest.raises(ElicitError) as info:
        run_graph_ray(graph, tmp_path, {"add": crash_on_t1_op1_s1}, console=quiet())
    message = str(info.value)
    assert message == (
        "stage 'train/t1/op1/s1' failed on a Ray worker: RuntimeError: simulated crash"
    )
    assert not (tmp_path / "policies" / "t1" / "op1" / "s1.json").exists()
    assert not (tmp_path / "report.json").exists()
    assert not (tmp_path / ".pipeline" / "lock").exists()
    resumed = run_graph_ray(graph, tmp_path, {"add": add_stage}, console=quiet())
    assert "collect/t0" in resumed.skipped and "collect/t1" in resumed.skipped
    assert {"train/t1/op1/s1", "evaluate/t1/op1/s1", "report"} <= set(resumed.ran)
    assert values(tmp_path, graph)["report"] == 1244


def test_elicit_error_in_a_stage_keeps_its_message(cluster, tmp_path):
    def bad_input(ctx: StageContext) -> None:
        raise ElicitError("episode 3 has NaN actions", "data/t0.json")

    graph = Graph([Stage("collect/t0", "bad", "data/t0.json")])
    with pytest.raises(ElicitError) as info:
        run_graph_ray(graph, tmp_path, {"bad": bad_input}, console=quiet())
    assert str(info.value) == (
        "stage 'collect/t0' failed on a Ray worker: data/t0.json: episode 3 has NaN actions"
    )


_LOCAL_SCRIPT = textwrap.dedent(
    """
    import sys
    sys.path.insert(0, sys.argv[2])  # elicit_jax through sys.path, as `python -m` in a checkout
    import elicit_jax
    from elicit_jax.artifact import make_header, read_json, write_json
    from elicit_jax.pipeline.graph import Graph, Stage
    from elicit_jax.pipeline.ray_runner import run_graph_ray
    from rich.console import Console

    def add(ctx):
        import elicit_jax
        total = ctx.config["value"] + sum(read_json(p)["value"] for p in ctx.inputs.values())
        write_json(ctx.output, {**make_header("test-add", 1, config=dict(ctx.config)),
                                "value": total, "package": elicit_jax.__file__})

    graph = Graph([Stage("a", "add", "a.json", {"value": 1}),
                   Stage("b", "add", "b.json", {"value": 2}, inputs={"x": "a"})])
    result = run_graph_ray(graph, sys.argv[1], {"add": add}, address="local", console=Console(),
                           show_progress=False)
    import ray
    print("ran", ",".join(result.ran), "connected-after", ray.is_initialized())
    print("driver-package", elicit_jax.__file__)
    """
)


def test_address_local_starts_and_stops_its_own_cluster(tmp_path):
    """Also: its workers import the driver's elicit_jax, not the installed one, and record the
    driver's command line, not their own."""
    import elicit_jax

    script = tmp_path / "local_ray.py"
    script.write_text(_LOCAL_SCRIPT)
    checkout = tmp_path / "checkout"
    checkout.mkdir()
    (checkout / "elicit_jax").symlink_to(Path(elicit_jax.__file__).parent)
    out = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "run"), str(checkout)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "RAY_ADDRESS": ""},
        cwd=tmp_path,  # Ray puts the driver's folder first on its workers' sys.path
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert "ran a,b connected-after False" in out.stdout
    b = read_json(tmp_path / "run" / "b.json")
    assert b["value"] == 3  # 2 + a's 1
    assert f"driver-package {checkout}" in out.stdout
    assert b["package"].startswith(str(checkout)), b["package"]
    command = b["provenance"]["command"]
    assert command == f"local_ray.py {tmp_path / 'run'} {checkout}", command


def test_missing_ray_is_a_one_line_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(ElicitError, match=r"pip install 'elicit-jax\[ray\]'"):
        import_ray()
