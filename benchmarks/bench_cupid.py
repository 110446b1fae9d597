"""CUPID's scoring cost: per-sample gradients, projection and the influence solve.

An ensemble of ``--members`` MLPs of ``--hidden`` (random weights: the cost does not depend on
them), 23-D observations, 7-D actions; ``--pairs`` training pairs (demos of 100 steps) and
``--rollouts`` × ``--steps`` recorded rollout steps with exploration noise. Prints wall and CPU
time of :func:`elicit_jax.curation.cupid.cupid_scores`, compilation included (CPU time is the
fairer figure on a shared machine).

Run: ``python benchmarks/bench_cupid.py --hidden 256,256`` (the ``cpu`` training profile's
size; docs/curation.md quotes it).
"""

from __future__ import annotations

import argparse
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hidden", default="256,256")
    ap.add_argument("--members", type=int, default=5)
    ap.add_argument("--pairs", type=int, default=4000)
    ap.add_argument("--rollouts", type=int, default=50)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--proj-dim", type=int, default=512)
    args = ap.parse_args()

    import jax
    import numpy as np

    from elicit_jax.curation.cupid import CupidConfig, cupid_scores
    from elicit_jax.data.demos import from_episodes
    from elicit_jax.policy.base import init_policy
    from elicit_jax.runtime import configure
    from elicit_jax.sim.trajectories import Trajectories

    configure()
    hidden = tuple(int(h) for h in args.hidden.split(","))
    rng = np.random.default_rng(0)
    policy = init_policy(
        jax.random.key(0), kind="mlp", obs_dim=23, action_dim=7, n_members=args.members,
        hidden=hidden,
    )  # fmt: skip
    eps = [
        {"obs": rng.normal(size=(100, 23)), "action": rng.uniform(-1, 1, (100, 7))}
        for _ in range(max(1, args.pairs // 100))
    ]
    new = from_episodes(eps, operators="op")
    m, t = args.rollouts, args.steps
    steps = Trajectories(
        rng.normal(size=(m * t, 23)).astype(np.float32),
        rng.uniform(-1, 1, (m * t, 7)).astype(np.float32),
        np.repeat(np.arange(m), t),
        rng.uniform(size=m) > 0.5,
        np.zeros(m),
        0.1,
        {},
    )
    wall, cpu = time.perf_counter(), time.process_time()
    scores = cupid_scores(policy, steps, new, None, CupidConfig(proj_dim=args.proj_dim))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    print(
        f"{args.members} x {hidden}: {scores.report['param_dim']} parameters per member, "
        f"{new.n_steps} training pairs, {m * t} rollout steps, proj_dim {args.proj_dim}: "
        f"{wall:.1f} s wall, {cpu:.1f} s CPU"
    )


if __name__ == "__main__":
    main()
