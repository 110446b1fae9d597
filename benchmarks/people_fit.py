"""What one prompt teaches the shipped simulated people (issue #31): per task, each person of
``pipelines/elicitation.toml``'s population watches 5 base demonstrations and fits its
parameters θ once (imitation forced to 1, the rest of its traits as drawn).

Per person: whether the base operator's θ lies in its reachable set; the distance of its θ to
the base operator's (Euclidean, each coordinate a fraction of its range) before and after; the
mean squared difference between its choices' and the base's imagined actions on the shown
states (both with the base's motor parameters and the people's watching tolerances; the
report's "ends as base" is this below 0.01) before and after; the fit's wall time. This script
reads the base operator's style to measure; the people never do.

Run: ``.venv/bin/python benchmarks/people_fit.py [--tasks reach-pillar round-nut]
[--out benchmarks/results/people-fit.md]`` (about 10 s for reach-pillar, 30 s per nut task).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from elicit_jax.elicit.people import SimulatedPerson, parse_person
from elicit_jax.elicit.people.imagine import action_error, imagine
from elicit_jax.elicit.people.learn import Shown, watching
from elicit_jax.pipeline.elicitation.spec import load_study
from elicit_jax.sim.collect import CollectConfig, collect_episodes
from elicit_jax.sim.env import make_task
from elicit_jax.sim.operators import full_choices, style_of


def task_rows(name: str, episodes: int, seed: int) -> list[str]:
    """Markdown rows, one per person of the task's shipped population."""
    (study_task,) = load_study("pipelines/elicitation.toml", "paper", (name,)).tasks
    task = make_task(name)
    got = collect_episodes(
        CollectConfig(task=name, operator="base", episodes=episodes, seed=seed, batch=episodes)
    )
    shown = [Shown(e["obs"].astype(float), e["action"].astype(float)) for e in got.episodes]
    states = [s.states for s in shown]
    base = style_of(name, "base")
    theirs = imagine(task, watching(base, dict(base.choices)), states)
    rows = []
    for i, spec in enumerate(study_task.people):
        traits = dataclasses.replace(parse_person(spec.partition(":")[2]), imitation=1.0)
        person = SimulatedPerson(task, traits, None)
        target = person.space.theta(full_choices(name, "base"))
        lo, hi = person.bounds
        reach = bool(np.all((target >= lo - 1e-9) & (target <= hi + 1e-9)))

        def measure(p: SimulatedPerson = person, t: np.ndarray = target) -> tuple[float, float]:
            d = float(np.linalg.norm((p.theta - t) / p.space.width))
            return d, action_error(imagine(task, watching(base, p.choices), states), theirs)

        d0, e0 = measure()
        start = time.perf_counter()
        person.memory.extend(shown)
        person.fit(0, "prompt")
        seconds = time.perf_counter() - start
        d1, e1 = measure()
        rows.append(
            f"| {name} | p{i} | {traits.style} | {traits.reach:.2f} | {'yes' if reach else 'no'} "
            f"| {d0:.2f} → {d1:.2f} | {e0:.3f} → {e1:.3f} | {'yes' if e1 < 0.01 else 'no'} "
            f"| {seconds:.1f} |"
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tasks", nargs="+", default=["reach-pillar", "round-nut"])
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    lines = [
        "| task | person | starts as | reach | base θ reachable | θ distance to base "
        "| imagined error vs base | as base | fit s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name in args.tasks:
        lines += task_rows(name, args.episodes, args.seed)
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
