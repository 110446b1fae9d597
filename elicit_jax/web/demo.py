"""Built-in inputs for ``elicit-jax serve --demo``: a small reach-pillar base, built once.

:func:`demo_inputs` makes what a session needs — base demonstrations, a base policy and
thresholds fitted on contrast sets — with the library's own stages, the quickstart's way:
20 demonstrations of the scripted ``base`` operator (it passes the pillar on the left), a
5 x 128-128 ensemble trained on them, and (λ, η) fitted on 4 held-out ``base``
demonstrations against 4 of ``conflict-over`` (it climbs over the pillar). Everything lands
in ``CACHE/serve-demo/<hash>/``, where the hash covers the recipe, the resolved training
config, the task's model, the scripted operators' code and the elicit-jax version, so a
changed recipe, training default or operator — or an upgrade — builds anew and an unchanged
one is reused (about a minute the first time on a 2-core CPU, instant after). The directory
is written atomically: a build cut short leaves nothing that looks finished.
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import json
from pathlib import Path
from typing import Any

from elicit_jax.errors import ElicitError

RECIPE_FILE = "recipe.json"
BASE_FILE = "base.parquet"
CONTRAST_FILE = "contrast.parquet"
SCORES_FILE = "contrast-scores.parquet"
POLICY_DIR = "policy"
THRESHOLDS_FILE = "thresholds.json"


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


def train_config(recipe: DemoRecipe) -> Any:
    """The ``TrainConfig`` the base policy is trained with (the ``cpu`` profile's defaults,
    with the recipe's sizes)."""
    from elicit_jax.policy.config import TrainConfig

    return TrainConfig.from_profile(
        "cpu",
        hidden=recipe.hidden,
        ensemble_size=recipe.ensemble_size,
        epochs=recipe.epochs,
        checkpoint_every=recipe.epochs // 4,
        progress_every=10,
    )


def recipe_hash(recipe: DemoRecipe) -> str:
    """SHA-256 of the recipe, its training config, the task's MJCF, the source of its
    scripted operators and the elicit-jax version."""
    from elicit_jax import __version__
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.operators import base as operator_base

    task = make_task(recipe.task)
    module = inspect.getmodule(type(_operator(task, recipe.operator)))
    parts = [
        json.dumps(dataclasses.asdict(recipe), sort_keys=True),
        json.dumps(train_config(recipe).to_dict(), sort_keys=True, default=str),
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


def _paths(root: Path) -> DemoInputs:
    return DemoInputs(root, root / BASE_FILE, root / POLICY_DIR, root / THRESHOLDS_FILE)


def demo_inputs(
    recipe: DemoRecipe = DemoRecipe(),
    root: str | Path | None = None,
    echo: Any = print,
) -> DemoInputs:
    """The demo inputs of ``recipe``: reused from the cache, or built there now.

    Args:
      recipe: what to build.
      root: cache root (default :func:`default_demo_root`); inputs go to ``root/<hash16>``.
      echo: where progress lines go.

    Returns:
      Paths of the base demonstrations, the policy run and the thresholds.
    """
    from elicit_jax.artifact import atomic_path, read_json, write_json

    digest = recipe_hash(recipe)
    out = Path(root or default_demo_root()) / digest[:16]
    if (out / RECIPE_FILE).is_file():
        stored = read_json(out / RECIPE_FILE)
        if stored.get("sha256") != digest:
            raise ElicitError("holds demo inputs of another recipe; remove it", out)
        return _paths(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    echo(f"building the demo inputs for {recipe.task} (once; cached in {out})")
    with atomic_path(out) as tmp:
        tmp.mkdir()
        _build(recipe, tmp, echo)
        write_json(
            tmp / RECIPE_FILE,
            {"kind": "serve-demo-inputs", "sha256": digest, "recipe": dataclasses.asdict(recipe)},
        )
    return _paths(out)


def _build(recipe: DemoRecipe, out: Path, echo: Any) -> None:
    from elicit_jax.compat.fit import FitJob, fit_scores_file
    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.compat.score_file import score_file
    from elicit_jax.data.demos import concat_demos, read_demos, write_demos
    from elicit_jax.policy.checkpoint import load_policy
    from elicit_jax.policy.train import train_policy
    from elicit_jax.sim.collect import CollectConfig, collect

    r = recipe
    sets = (
        (BASE_FILE, r.operator, r.episodes, r.seed),
        ("holdout.parquet", r.operator, r.contrast_episodes, r.seed + 1),
        ("incompatible.parquet", r.incompatible_operator, r.contrast_episodes, r.seed + 2),
    )
    for name, op, n, seed in sets:
        echo(f"  collect {n} demonstrations of '{op}'")
        collect(CollectConfig(task=r.task, operator=op, episodes=n, seed=seed), out / name)
    parts = [read_demos(out / name) for name, *_ in sets[1:]]
    write_demos(out / CONTRAST_FILE, concat_demos(parts))
    echo(f"  train the base policy ({r.ensemble_size} x {r.hidden}, {r.epochs} epochs)")
    train_policy(
        read_demos(out / BASE_FILE),
        train_config(r),
        out / POLICY_DIR,
        inputs={"demos": out / BASE_FILE},
        quiet=True,
    )
    echo("  fit the thresholds on the contrast sets")
    score_file(
        load_policy(out / POLICY_DIR),
        out / CONTRAST_FILE,
        out / SCORES_FILE,
        ScoreConfig(),
        policy_path=out / POLICY_DIR,
    )
    job = FitJob(
        compatible=f"operator:{r.operator}", incompatible=f"operator:{r.incompatible_operator}"
    )
    fit_scores_file(out / SCORES_FILE, out / THRESHOLDS_FILE, job)
