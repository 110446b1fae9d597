"""Built-in inputs for ``elicit-jax serve --demo``: a small reach-pillar base, built once.

It lives beside the pipeline engine it runs (``web/`` serves sessions and imports nothing from
``pipeline/``; the CLI builds the inputs here and hands ``web/`` their paths), and its cache
directory is the only cache of these inputs.

:func:`demo_inputs` makes what a session needs — base demonstrations, a base policy and
thresholds fitted on contrast sets — by running the quickstart's own stages on the pipeline
engine (:func:`demo_graph`: a filtering definition of one task, cut down to the stages the
thresholds need): 20 demonstrations of the scripted ``base`` operator (it passes the pillar
on the left), a 5 x 128-128 ensemble trained on them, and (λ, η) fitted on 4 held-out
``base`` demonstrations against 4 of ``conflict-over`` (it climbs over the pillar). The local
runner writes them to ``CACHE/serve-demo/<hash>/``, a pipeline run directory, where the hash
covers the recipe, the resolved training config, every stage's config, the task's model, the
scripted operators' code and the elicit-jax version, so a changed recipe, default or operator
— or an upgrade — builds anew and an unchanged one is reused (about a minute the first time
on a 2-core CPU, instant after). Each stage is written atomically and ``recipe.json`` last: a
build cut short leaves nothing that looks finished, and the next call resumes it from the
stages it finished.
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from elicit_jax.errors import ElicitError

RECIPE_FILE = "recipe.json"
MODEL = "mlp"
LAYOUT = "pipeline-run/1"
"""The cache directory's layout (part of the hash: a cache of another layout is not reused)."""
DEMO_SOURCE = "serve --demo"
"""How the demo's definition is named in its run manifest and errors."""


@dataclasses.dataclass(frozen=True)
class DemoRecipe:
    """How the demo inputs are made.

    Attributes:
      task: the task (reach-pillar: small and fast).
      operator: the base operator's scripted style.
      episodes: base demonstrations.
      contrast_episodes: demonstrations in each contrast set.
      incompatible_operator: the known-conflicting style of the incompatible contrast set.
      seed: collection seed (held-out and incompatible sets use seed + 1 and seed + 2).
      hidden: hidden sizes of the ensemble members.
      ensemble_size: members.
      epochs: training epochs.
    """

    task: str = "reach-pillar"
    operator: str = "base"
    episodes: int = 20
    contrast_episodes: int = 4
    incompatible_operator: str = "conflict-over"
    seed: int = 0
    hidden: tuple[int, ...] = (128, 128)
    ensemble_size: int = 5
    epochs: int = 200


@dataclasses.dataclass(frozen=True)
class DemoInputs:
    """Paths of the built inputs."""

    dir: Path
    base_demos: Path
    policy: Path
    thresholds: Path


def _train_overrides(recipe: DemoRecipe) -> dict[str, Any]:
    return {
        "hidden": list(recipe.hidden),
        "ensemble_size": recipe.ensemble_size,
        "epochs": recipe.epochs,
        "checkpoint_every": recipe.epochs // 4,
        "progress_every": 10,
    }


def train_config(recipe: DemoRecipe) -> Any:
    """The ``TrainConfig`` the base policy is trained with (the ``cpu`` profile's defaults,
    with the recipe's sizes): the one the train stage of :func:`demo_graph` resolves."""
    from elicit_jax.policy.config import TrainConfig

    return TrainConfig.from_profile("cpu", model=MODEL, **_train_overrides(recipe))


def demo_definition(recipe: DemoRecipe) -> dict[str, Any]:
    """The recipe as a filtering pipeline definition (parsed TOML) of one task and one
    model. The format asks for a D_new; the demo never runs its stages (:func:`demo_graph`)."""
    r = recipe
    task = {
        "name": r.task,
        "base_operator": r.operator,
        "operators": [r.incompatible_operator],
        "base_episodes": r.episodes,
        "holdout_episodes": r.contrast_episodes,
        "incompatible_operator": r.incompatible_operator,
        "incompatible_episodes": r.contrast_episodes,
    }
    head = {"name": "serve-demo", "profile": "cpu", "seeds": [0], "models": [MODEL]}
    head |= {"methods": ["base", "filtered"], "collect_seed": r.seed}
    return {"pipeline": head, "task": [task], "train": _train_overrides(r)}


def _targets(recipe: DemoRecipe) -> tuple[str, str, str]:
    """Ids of the stages whose outputs the demo serves: D_base, the base policy, (λ, η)."""
    cell = f"{recipe.task}/{MODEL}"
    return f"collect/{recipe.task}/base", f"train/{cell}/base", f"fit-thresholds/{cell}"


def demo_graph(recipe: DemoRecipe) -> Any:
    """The stage graph that builds the demo inputs: the pipeline's plan of
    :func:`demo_definition`, kept to the stages the base demos, the base policy and the
    fitted thresholds need (collect D_base and the two contrast sets, train, score the
    contrast sets, fit)."""
    from elicit_jax.pipeline.graph import Graph
    from elicit_jax.pipeline.study_kinds import plan_data

    _, full, _ = plan_data(demo_definition(recipe), DEMO_SOURCE)
    keep, frontier = set(), set(_targets(recipe))
    while frontier:
        keep |= frontier
        frontier = {i for sid in frontier for i in full[sid].inputs.values()} - keep
    return Graph(s for s in full.order if s.id in keep)


def recipe_hash(recipe: DemoRecipe) -> str:
    """SHA-256 of the cache layout, the recipe, its training config, its stage graph (every
    stage's resolved config), the task's MJCF, the source of its scripted operators and the
    elicit-jax version."""
    from elicit_jax import __version__
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.operators import base as operator_base

    task = make_task(recipe.task)
    module = inspect.getmodule(type(_operator(task, recipe.operator)))
    stages = [[s.id, s.kind, s.output, dict(s.config), dict(s.inputs)] for s in demo_graph(recipe)]
    parts = [
        LAYOUT,
        json.dumps(dataclasses.asdict(recipe), sort_keys=True),
        json.dumps(train_config(recipe).to_dict(), sort_keys=True, default=str),
        json.dumps(stages, sort_keys=True, default=str),
        __version__,
        task.xml(),
        inspect.getsource(operator_base),
        inspect.getsource(module) if module else "",
    ]
    return hashlib.sha256("\0".join(parts).encode()).hexdigest()


def _operator(task: Any, name: str) -> Any:
    from elicit_jax.sim.operators import make_operator

    return make_operator(task, name)


def default_demo_root() -> Path:
    """``<cache>/serve-demo``, beside JAX's compilation cache."""
    from elicit_jax.runtime import default_cache_dir

    return default_cache_dir().parent / "serve-demo"


def _paths(root: Path, recipe: DemoRecipe) -> DemoInputs:
    graph = demo_graph(recipe)
    base, policy, thresholds = (root / graph[sid].output for sid in _targets(recipe))
    return DemoInputs(root, base, policy, thresholds)


def demo_inputs(
    recipe: DemoRecipe,
    root: str | Path | None,
    *,
    echo: Callable[[str], None],
    console: Any,
) -> DemoInputs:
    """The demo inputs of ``recipe``: reused from the cache, or built there now.

    Args:
      recipe: what to build.
      root: cache root (default :func:`default_demo_root`); inputs go to ``root/<hash16>``.
      echo: where the one-line messages go (the caller's: nothing here prints).
      console: the ``rich`` console the stages show their progress on (the caller's).

    Returns:
      Paths of the base demonstrations, the policy run and the thresholds.
    """
    from elicit_jax.artifact import read_json, write_json
    from elicit_jax.pipeline.run import write_manifest
    from elicit_jax.pipeline.runner import run_graph, run_lock
    from elicit_jax.pipeline.study_kinds import plan_data

    digest = recipe_hash(recipe)
    out = Path(root or default_demo_root()) / digest[:16]
    if (out / RECIPE_FILE).is_file():
        stored = read_json(out / RECIPE_FILE)
        if stored.get("sha256") != digest:
            raise ElicitError("holds demo inputs of another recipe; remove it", out)
        return _paths(out, recipe)
    echo(f"building the demo inputs for {recipe.task} (once; cached in {out})")
    graph = demo_graph(recipe)
    spec, _, registry = plan_data(demo_definition(recipe), DEMO_SOURCE)
    out.mkdir(parents=True, exist_ok=True)
    with run_lock(out):
        write_manifest(out, spec, graph)
        run_graph(graph, out, registry(), console=console, lock=False)
        write_json(
            out / RECIPE_FILE,
            {"kind": "serve-demo-inputs", "sha256": digest, "recipe": dataclasses.asdict(recipe)},
        )
    return _paths(out, recipe)
