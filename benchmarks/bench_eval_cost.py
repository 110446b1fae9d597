"""Evaluation cost on robosuite, before and after the speed-up of ``make_env(fast=True)``.

**old** builds robosuite environments exactly as robosuite does (``fast=False``), **new** with
the speed-up (each robot remembers its action size:
:func:`elicit_jax.sim.robosuite_env.remember_action_dims`). Both roll the same policy out from
the same seeded initial states, and every rollout (serial) or round (pool) checks that they
give the same observations, successes and lengths; the run stops if they differ.

- ``--mode serial`` (default; the steadier measurement on a shared machine): one environment of
  each kind in this process, alternating old and new every rollout. ``--control`` builds both
  without the speed-up: the ratio the machine's noise alone gives (an A/A run).
- ``--mode pool``: two pools of robosuite workers (``--workers`` each, as the ``evaluate``
  stage starts them), each round through the evaluation's own loop
  (:func:`elicit_jax.sim.rollout_robosuite.rollout_policy`: stop at success, every worker
  refilled), alternating which pool goes first.

The ratio old / new seconds is taken within a round and reported as the median [min–max] over
rounds, so load drifting between rounds cancels. The policy is the ``cpu`` profile's network
(5 members of 2 × 256) at its seed-0 initialization: it never succeeds, so every rollout runs
to ``--horizon``, the costly case of a data-starved base policy. A timing, not a test: the
machine is shared.

    python benchmarks/bench_eval_cost.py --rounds 5 --rollouts 4 --horizon 100 \
        --json benchmarks/results/eval-cost.json                       # ~2 min of CPU
    python benchmarks/bench_eval_cost.py --rounds 4 --rollouts 4 --horizon 100 --control  # A/A
    python benchmarks/bench_eval_cost.py --mode pool --rollouts 6 --horizon 150
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np


def _untrained_policy():
    """The cpu profile's policy shape (5 × MLP 2 × 256), untrained: its cost per step is the
    trained one's, and its rollouts run to the horizon."""
    import jax

    from elicit_jax.policy.base import init_policy
    from elicit_jax.sim.registry import ACTION_DIM, OBS_DIM

    return init_policy(
        jax.random.key(0), kind="mlp", obs_dim=OBS_DIM, action_dim=ACTION_DIM, n_members=5,
        hidden=(256, 256), dropout=0.5,
    )  # fmt: skip


def log(name: str, value: object) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {name}: {value}", flush=True)


def outcome_key(out: dict) -> tuple:
    """What an evaluation reports of its rollouts: successes, lengths, initial states."""
    return (
        out["success"].tobytes(),
        out["steps_to_success"].tobytes(),
        out["unstable"].tobytes(),
        out["init_obs"].tobytes(),
    )


def run(args: argparse.Namespace) -> dict:
    from elicit_jax.policy.base import jitted_act
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.rollout_robosuite import SHARED_HORIZON, EnvPool, rollout_policy

    spec = make_task(args.task).spec
    policy = _untrained_policy()
    act = jitted_act()
    seeds = np.arange(1000, 1000 + args.rollouts)
    pools = {
        name: EnvPool(spec, args.workers, SHARED_HORIZON, fast=(name == "new"))
        for name in ("old", "new")
    }
    rounds = []
    try:
        for pool in pools.values():  # compile and warm up every worker
            rollout_policy(spec, act, policy, seeds[: args.workers], 2, args.workers, pool)
        for r in range(args.rounds):
            order = ("old", "new") if r % 2 == 0 else ("new", "old")
            secs, steps, keys = {}, {}, {}
            for name in order:
                t0 = time.perf_counter()
                out = rollout_policy(spec, act, policy, seeds, args.horizon, args.workers,
                                     pools[name])  # fmt: skip
                secs[name] = time.perf_counter() - t0
                steps[name] = int(out["env_steps"])
                keys[name] = outcome_key(out)
            same = keys["old"] == keys["new"]
            row = {
                "round": r,
                "old_s": secs["old"],
                "new_s": secs["new"],
                "env_steps": steps["new"],
                "old_steps_per_s": steps["old"] / secs["old"],
                "new_steps_per_s": steps["new"] / secs["new"],
                "ratio": secs["old"] / secs["new"],
                "identical": same,
            }
            rounds.append(row)
            log(f"round {r}", {k: round(v, 3) if isinstance(v, float) else v
                              for k, v in row.items()})  # fmt: skip
            if not same:
                raise SystemExit("old and new evaluations differ: the speed-up changed a number")
    finally:
        for pool in pools.values():
            pool.close()
    ratios = sorted(r["ratio"] for r in rounds)
    return {
        "task": args.task,
        "mode": "pool",
        "workers": args.workers,
        "rollouts": args.rollouts,
        "horizon": args.horizon,
        "load_avg_1m": os.getloadavg()[0],
        "rounds": rounds,
        "median_ratio": float(np.median(ratios)),
        "min_ratio": ratios[0],
        "max_ratio": ratios[-1],
    }


def run_serial(args: argparse.Namespace) -> dict:
    """One environment of each kind in this process, the same policy and seeds, alternating
    old and new every rollout (load drifts over seconds, so close alternation cancels most of
    it); per round, the ratio of the two loops' seconds."""

    from elicit_jax.policy.base import jitted_act
    from elicit_jax.sim import robosuite_env as rs
    from elicit_jax.sim.env import make_task

    spec = make_task(args.task).spec
    policy = _untrained_policy()
    act = jitted_act()
    fast = {"old": False, "new": not args.control}
    envs = {name: rs.make_env(spec, 1_000_000, fast=fast[name]) for name in ("old", "new")}

    def rollout(env, seed: int) -> tuple[float, np.ndarray]:
        obs = rs.flat_obs(rs.reset_seeded(env, seed), spec.obs_keys)
        carry, seen = policy.init_carry(1), []
        t0 = time.perf_counter()
        for _ in range(args.horizon):
            carry, a = act(policy, carry, obs[None].astype(np.float32))
            d, *_ = env.step(np.asarray(a, np.float64)[0])
            obs = rs.flat_obs(d, spec.obs_keys)
            seen.append(np.append(obs, rs.success(env)))
        return time.perf_counter() - t0, np.stack(seen)

    rollout(envs["old"], 0)  # compile
    rounds = []
    for r in range(args.rounds):
        secs = {"old": 0.0, "new": 0.0}
        for k in range(args.rollouts):
            seed = 1000 + k
            order = ("old", "new") if (r + k) % 2 == 0 else ("new", "old")
            seen = {}
            for name in order:
                dt, seen[name] = rollout(envs[name], seed)
                secs[name] += dt
            if not np.array_equal(seen["old"], seen["new"]):
                raise SystemExit("old and new rollouts differ: the speed-up changed a number")
        steps = args.rollouts * args.horizon
        row = {"round": r, "old_s": secs["old"], "new_s": secs["new"], "env_steps": steps,
               "old_steps_per_s": steps / secs["old"], "new_steps_per_s": steps / secs["new"],
               "ratio": secs["old"] / secs["new"], "identical": True}  # fmt: skip
        rounds.append(row)
        log(f"round {r}", {k: round(v, 3) if isinstance(v, float) else v for k, v in row.items()})
    for env in envs.values():
        env.close()
    ratios = sorted(r["ratio"] for r in rounds)
    return {"task": args.task, "mode": "serial", "control": args.control,
            "rollouts": args.rollouts,
            "horizon": args.horizon, "load_avg_1m": os.getloadavg()[0], "rounds": rounds,
            "median_ratio": float(np.median(ratios)), "min_ratio": ratios[0],
            "max_ratio": ratios[-1]}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="robosuite-round")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--rollouts", type=int, default=6)
    parser.add_argument("--horizon", type=int, default=150)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--mode", choices=("serial", "pool"), default="serial")
    parser.add_argument(
        "--control",
        action="store_true",
        help="serial mode: build both environments without the speed-up (an A/A run: the "
        "ratio the machine's noise alone gives)",
    )
    parser.add_argument("--json", default="")
    args = parser.parse_args()
    result = run_serial(args) if args.mode == "serial" else run(args)
    print(
        f"old / new seconds per evaluation: median {result['median_ratio']:.3f}× "
        f"[{result['min_ratio']:.3f}–{result['max_ratio']:.3f}] over {args.rounds} rounds; "
        "every round identical successes, lengths and initial states"
    )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
