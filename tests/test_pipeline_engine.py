"""The pipeline engine: skip, resume and invalidation semantics on cheap test-local stages."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from rich.console import Console

from elicit_jax.artifact import make_header, read_header, read_json, write_json
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.graph import Graph, Stage
from elicit_jax.pipeline.runner import (
    StageContext,
    record_path,
    run_graph,
    run_lock,
    stage_up_to_date,
    summary_rows,
)

CALLS: list[str] = []


def add_stage(ctx: StageContext) -> None:
    """Fake work: output value = config 'value' + the sum of the input artifacts' values."""
    CALLS.append(ctx.stage.id)
    total = int(ctx.config.get("value", 0))
    for path in ctx.inputs.values():
        total += read_json(path)["value"]
    header = make_header("test-add", 1, config=dict(ctx.config), inputs=dict(ctx.inputs))
    header.update(value=total, nonce=time.time_ns())
    write_json(ctx.output, header)


def boom_stage(ctx: StageContext) -> None:
    CALLS.append(ctx.stage.id)
    raise RuntimeError("simulated crash")


REGISTRY = {"add": add_stage}


def diamond(d_value: int = 4) -> Graph:
    """a -> b -> c, a -> d; values 1, 2, 3, d_value."""
    return Graph(
        [
            Stage("a", "add", "a.json", {"value": 1}),
            Stage("b", "add", "sub/b.json", {"value": 2}, inputs={"x": "a"}),
            Stage("c", "add", "c.json", {"value": 3}, inputs={"x": "b"}),
            Stage("d", "add", "d.json", {"value": d_value}, inputs={"x": "a"}),
        ]
    )


def run(graph: Graph, run_dir: Path, registry=None):
    CALLS.clear()
    console = Console(file=open(os.devnull, "w"))  # noqa: SIM115
    return run_graph(graph, run_dir, registry or REGISTRY, console=console)


def test_first_run_runs_everything_in_order_and_second_run_does_nothing(tmp_path):
    result = run(diamond(), tmp_path)
    assert CALLS == ["a", "b", "d", "c"]  # breadth-first waves, insertion order within a wave
    # c = 3 + b = 3 + (2 + a) = 3 + 2 + 1 = 6; d = 4 + 1 = 5
    assert read_json(tmp_path / "c.json")["value"] == 6
    assert read_json(tmp_path / "d.json")["value"] == 5
    assert result.ran == ["a", "b", "d", "c"]
    header = read_header(record_path(tmp_path, diamond()["c"]))
    assert header["kind"] == "pipeline-stage"
    assert header["inputs"]["x"]["path"].endswith("sub/b.json")
    second = run(diamond(), tmp_path)
    assert CALLS == []
    assert second.skipped == ["a", "b", "d", "c"]
    assert summary_rows(second) == [("add", 4, 0, 4, 0.0)]


def test_deleting_one_artifact_reruns_exactly_that_stage_and_its_dependents(tmp_path):
    run(diamond(), tmp_path)
    (tmp_path / "sub" / "b.json").unlink()
    result = run(diamond(), tmp_path)
    assert CALLS == ["b", "c"]
    assert result.skipped == ["a", "d"]


def test_changed_config_reruns_only_what_it_affects(tmp_path):
    run(diamond(), tmp_path)
    run(diamond(d_value=40), tmp_path)
    assert CALLS == ["d"]
    assert read_json(tmp_path / "d.json")["value"] == 41  # 40 + a's 1
    run(diamond(d_value=40), tmp_path)
    assert CALLS == []


def test_tampered_output_or_record_reruns(tmp_path):
    run(diamond(), tmp_path)
    path = tmp_path / "d.json"
    data = read_json(path)
    data["value"] = 99
    write_json(path, data)  # edited by hand: the recorded output hash no longer matches
    record_path(tmp_path, diamond()["c"]).unlink()
    run(diamond(), tmp_path)
    assert CALLS == ["d", "c"]


def test_crash_mid_grid_keeps_finished_stages_and_resumes(tmp_path):
    with pytest.raises(RuntimeError, match="simulated crash"):
        run(
            diamond(),
            tmp_path,
            {"add": lambda ctx: (boom_stage if ctx.stage.id == "d" else add_stage)(ctx)},
        )
    assert CALLS == ["a", "b", "d"]
    assert not (tmp_path / "d.json").exists()
    assert not (tmp_path / ".pipeline" / "lock").exists()
    result = run(diamond(), tmp_path)
    assert CALLS == ["d", "c"]
    assert result.skipped == ["a", "b"]


def test_stage_that_writes_nothing_is_an_error(tmp_path):
    graph = Graph([Stage("a", "noop", "a.json")])
    with pytest.raises(ElicitError, match="without writing its output"):
        run(graph, tmp_path, {"noop": lambda ctx: None})
    assert not stage_up_to_date(tmp_path, graph, graph["a"])


def test_unregistered_kind_fails_before_running_anything(tmp_path):
    graph = Graph([Stage("a", "add", "a.json"), Stage("b", "mystery", "b.json")])
    with pytest.raises(ElicitError, match="mystery"):
        run(graph, tmp_path)
    assert CALLS == []


_KILL_SCRIPT = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from elicit_jax.artifact import atomic_path, write_json
    from elicit_jax.pipeline.graph import Graph, Stage
    from elicit_jax.pipeline.runner import run_graph
    from rich.console import Console

    def slow(ctx):
        if ctx.stage.id == "b":
            with atomic_path(ctx.output) as tmp:
                tmp.write_text("half")
                Path(sys.argv[2]).write_text("started")
                time.sleep(60)
        write_json(ctx.output, {"kind": "test", "value": 1, "id": ctx.stage.id})

    graph = Graph([
        Stage("a", "slow", "a.json"),
        Stage("b", "slow", "b.json", inputs={"x": "a"}),
        Stage("c", "slow", "c.json", inputs={"x": "b"}),
    ])
    run_graph(graph, sys.argv[1], {"slow": slow}, console=Console(), show_progress=False)
    """
)


def test_killed_process_resumes_where_it_stopped(tmp_path):
    run_dir, marker = tmp_path / "run", tmp_path / "started"
    script = tmp_path / "kill_me.py"
    script.write_text(_KILL_SCRIPT)
    proc = subprocess.Popen([sys.executable, str(script), str(run_dir), str(marker)])
    deadline = time.monotonic() + 60
    while not marker.exists():
        assert proc.poll() is None, "runner exited before reaching stage b"
        assert time.monotonic() < deadline
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert (run_dir / "a.json").exists()
    assert not (run_dir / "b.json").exists()  # the half-written artifact never became visible
    assert (run_dir / ".pipeline" / "lock").exists()  # stale lock of a dead process
    assert list(run_dir.glob(".b.json.*.tmp"))  # the interrupted write's temporary

    def fast(ctx):
        CALLS.append(ctx.stage.id)
        write_json(ctx.output, {"kind": "test", "value": 2, "id": ctx.stage.id})

    graph = Graph(
        [
            Stage("a", "slow", "a.json"),
            Stage("b", "slow", "b.json", inputs={"x": "a"}),
            Stage("c", "slow", "c.json", inputs={"x": "b"}),
        ]
    )
    result = run(graph, run_dir, {"slow": fast})
    assert CALLS == ["b", "c"]
    assert result.skipped == ["a"]
    assert not list(run_dir.glob(".*.tmp"))


def test_live_lock_of_another_process_refuses(tmp_path):
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        lock = tmp_path / ".pipeline" / "lock"
        lock.parent.mkdir(parents=True)
        lock.write_text(str(sleeper.pid))
        with pytest.raises(ElicitError, match=f"pid {sleeper.pid}"), run_lock(tmp_path):
            pass
        assert lock.exists()
    finally:
        sleeper.kill()
        sleeper.wait()


def test_graph_rejects_cycles_duplicates_and_unknown_inputs():
    with pytest.raises(ElicitError, match="cycle"):
        Graph(
            [Stage("a", "add", "a", inputs={"x": "b"}), Stage("b", "add", "b", inputs={"x": "a"})]
        )
    with pytest.raises(ElicitError, match="duplicate stage id"):
        Graph([Stage("a", "add", "a"), Stage("a", "add", "b")])
    with pytest.raises(ElicitError, match="both write"):
        Graph([Stage("a", "add", "x"), Stage("b", "add", "x")])
    with pytest.raises(ElicitError, match="unknown stage 'zz'"):
        Graph([Stage("a", "add", "a", inputs={"x": "zz"})])
    assert diamond().dependents("a") == {"b", "c", "d"}
    assert diamond().dependents("b") == {"c"}


def test_stage_config_is_frozen_and_json_normalised():
    stage = Stage("a", "add", "a.json", {"sizes": (1, 2)})
    assert json.loads(json.dumps(dict(stage.config))) == {"sizes": [1, 2]}
    with pytest.raises(TypeError):
        stage.config["sizes"] = 3  # type: ignore[index]
    assert Stage("x/y z", "add", "o").record_name == "x__y_z.json"
