"""Run a shipped pipeline definition end to end at tiny sizes, before committing to the long run.

The definition keeps everything that shapes the stage graph — its tasks, operators, methods,
models, profile overrides, [sensitivity], [scorer] — and only the sizes shrink: a few
demonstrations per set, tiny networks trained for a few epochs with two checkpoints (the
scorer's a little wider, so it stays a policy of its own — also under a profile where the real
one trains as the base policy and is not planned), a few rollouts, two training seeds,
two λ points on one held-out seed. Every stage kind the real run uses runs once for
real (collection, training, scoring, the fit, every filter, DemInf, Demo-SCORE rollouts and
classifier, evaluation, the report). The numbers mean nothing; the point is that the long
run cannot fail on a wiring error after hours.

    python benchmarks/smoke_pipeline.py filtering --profile cpu --tasks square-nut
    python benchmarks/smoke_pipeline.py models --profile cpu --out /tmp/smoke-models
    python benchmarks/smoke_pipeline.py phenomenon-robosuite --tasks robosuite-round \
        --sizes default,paper                  # named sizes shrink too (4 + 2 per operator)

Writes the tiny definition next to the run (``<out>/tiny.toml``) and prints the stage summary.
"""

from __future__ import annotations

import argparse
import time
import tomllib
from pathlib import Path
from typing import Any

TINY_TASK = {
    "base_episodes": 6,
    "new_episodes": 5,
    "holdout_episodes": 3,
    "incompatible_episodes": 2,
}
TINY_TRAIN = {
    "hidden": [16, 16],
    "ensemble_size": 2,
    "epochs": 6,
    "checkpoint_every": 3,
    "progress_every": 3,
    "batch_size": 128,
}

TINY_SCORER_HIDDEN = [24, 24]
"""A ``[scorer]``'s hidden sizes in the smoke run: tiny, and unlike :data:`TINY_TRAIN`'s."""


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int | float):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML here")


def _table(name: str, table: dict[str, Any], out: list[str], array: bool = False) -> None:
    scalars = {k: v for k, v in table.items() if not isinstance(v, dict)}
    out.append(f"[[{name}]]" if array else f"[{name}]")
    out += [f"{k} = {_value(v)}" for k, v in scalars.items()]
    out.append("")
    for k, v in table.items():
        if isinstance(v, dict):
            _table(f"{name}.{k}", v, out)


def to_toml(data: dict[str, Any]) -> str:
    """TOML for the subset a pipeline definition uses (tables, arrays of tables, scalars)."""
    out: list[str] = [
        "# tiny smoke-test copy of a shipped definition (benchmarks/smoke_pipeline.py)"
    ]
    for name, value in data.items():
        if isinstance(value, list) and value and isinstance(value[0], dict):
            for item in value:
                _table(name, item, out, array=True)
        else:
            _table(name, value, out)
    return "\n".join(out) + "\n"


def shrink(data: dict[str, Any]) -> dict[str, Any]:
    """The same definition at tiny sizes (graph shape unchanged)."""
    data = dict(data)
    data["pipeline"] = {**data["pipeline"], "seeds": [0, 1]}
    data["task"] = [{**t, **TINY_TASK, **_tiny_sizes(t)} for t in data["task"]]
    data["train"] = {**data.get("train", {}), **TINY_TRAIN}
    if "scorer" in data:  # tiny too, and still unlike the compared policies (so it is planned)
        data["scorer"] = {**data["scorer"], **TINY_TRAIN, "hidden": TINY_SCORER_HIDDEN}
    data["evaluate"] = {**data.get("evaluate", {}), "rollouts": 4}
    demo_score = data.get("demo_score", {})
    classifier = {**demo_score.get("classifier", {}), "steps": 100}
    data["demo_score"] = {**demo_score, "rollouts": 4, "classifier": classifier}
    profiles = {}
    for name, prof in data.get("profiles", {}).items():
        prof = {k: v for k, v in prof.items() if k not in ("train", "pipeline", "scorer")}
        profiles[name] = prof
    data["profiles"] = profiles
    if "sensitivity" in data:
        data["sensitivity"] = {**data["sensitivity"], "points": 2, "seeds": [100]}
    return data


def _tiny_sizes(task: dict[str, Any]) -> dict[str, Any]:
    """A task's named sizes shrunk too, each still unlike the tiny default counts (so a
    ``--sizes default,NAME`` smoke run plans both)."""
    if "sizes" not in task:
        return {}
    small = {"base_episodes": TINY_TASK["base_episodes"] - 2, "new_episodes": 2}
    return {"sizes": {name: dict(small) for name in task["sizes"]}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("definition", help="a shipped definition name or a TOML file")
    parser.add_argument("--profile", default=None)
    parser.add_argument("--tasks", default=None, help="comma-separated tasks")
    parser.add_argument("--sizes", default=None, help="named sizes, e.g. default,paper")
    parser.add_argument("--out", default=None, help="run directory [/tmp/smoke-<name>]")
    args = parser.parse_args()

    from elicit_jax.runtime import configure

    configure()
    from rich.console import Console

    from elicit_jax.pipeline.run import PipelineRunConfig, run_pipeline
    from elicit_jax.pipeline.spec import resolve_path

    source = resolve_path(args.definition)
    out = Path(args.out or f"/tmp/smoke-{source.stem}")
    out.mkdir(parents=True, exist_ok=True)
    tiny = out / "tiny.toml"
    tiny.write_text(to_toml(shrink(tomllib.loads(source.read_text()))))
    tasks = tuple(t for t in (args.tasks or "").split(",") if t) or None
    t0 = time.perf_counter()
    outcome = run_pipeline(
        PipelineRunConfig(
            pipeline=str(tiny),
            profile=args.profile,
            out=str(out / "run"),
            progress=False,
            tasks=tasks,
            sizes=args.sizes,
        ),
        console=Console(),
    )
    print(
        f"smoke run of {source.name} ({args.profile or 'its own'} profile): "
        f"{len(outcome.result.ran)} stages ran in {time.perf_counter() - t0:.0f} s; "
        f"report {outcome.report_md}"
    )


if __name__ == "__main__":
    main()
