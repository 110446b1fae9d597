"""Rollout speed with the policy in the loop: MJX, C MuJoCo, and a robomimic-style reference.

All three run square-nut with a paper-sized policy (MLP ensemble, 5 members, 2 x 1024) from
the same seeded initial states, side by side in one process:

- ``mjx``: one jitted function (vmapped environments, policy inside the loop);
- ``mujoco``: elicit-jax's C backend (thread pool over MjData, one batched policy call per
  control step);
- ``reference``: robomimic-style: one environment, one policy call per step, rollouts one
  after another, on C MuJoCo.

Reported: env-steps/s (control steps of all environments per second), physics steps/s, the
policy-FLOP bound (matmul GFLOP/s measured here / 10.8 MFLOP per policy step) and the fraction
of it reached, the C backend's speed-up over the reference, the MJX compile time cold (empty
cache, fresh process) and warm (persistent cache, fresh process), and scaling with the number
of rollouts (16 -> 50 -> 200 -> 1000). The policy is freshly initialised, so no rollout
succeeds and every rollout runs all its steps.

Steps per second do not need the task's full horizon (500 for square-nut): each contender runs
a fixed number of control steps, and the scaling table uses ``--scaling-horizon`` steps per
rollout (default 10) so that 1000 MJX rollouts finish in bounded time. Both are printed.

MJX with 1000 environments used to hang at 0% CPU: jaxlib 0.10's batched LAPACK kernels (MJX's
Cholesky solves) split big batches onto XLA's CPU thread pool and block waiting for them, and
two concurrent solves exhausted the 2-thread pool of a 2-core machine.
:func:`elicit_jax.runtime.configure` (``mjx=True``, as here) gives the pool at least 4 threads
(``PJRT_NPROC``).

With ``--robosuite TASK`` (needs the robosuite extra) it instead compares, in one run and
with the same paper-sized policy and the same initial-state seeds, elicit-jax's robosuite
backend (worker processes, one environment each, one batched policy call per control step)
with a robomimic-style serial loop (one environment in this process, one policy call per
step, rollouts one after another, success checked every step as robomimic's rollout helper
does), and with the machine's ceiling: as many copies of the serial loop as CPUs, in their own
processes, sharing nothing. Round after round (``--rs-rounds``); reported: env-steps/s of
each, the median ratio against the target (0.8 x CPUs x serial) and against the ceiling, and
the share of wall time spent in policy calls. Environment construction is not timed.

Usage: python benchmarks/bench_rollouts.py [--quick] [--sizes 16 50 200 1000]
    [--scaling-horizon 10] [--task square-nut] [--no-compile-times] [--json out.json]
       python benchmarks/bench_rollouts.py --robosuite robosuite-square [--workers N]
    [--rs-rollouts 6] [--rs-horizon 100] [--rs-rounds 3] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

from elicit_jax.runtime import configure

configure(mjx=True)

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from bench_score import paper_policy  # noqa: E402

from elicit_jax.sim.env import make_task  # noqa: E402
from elicit_jax.sim.evaluate import rollout_mujoco_policy  # noqa: E402
from elicit_jax.sim.rollout_mjx import rollout_fn  # noqa: E402
from elicit_jax.sim.rollout_mujoco import BatchSim  # noqa: E402

HIDDEN = (1024, 1024)
MEMBERS = 5
OBS, ACT = 23, 7
FLOP_PER_STEP = 2 * MEMBERS * (OBS * 1024 + 1024 * 1024 + 1024 * ACT)  # 10.8 MFLOP


_members = jax.jit(lambda p, o: p.members(o))


def matmul_gflops(policy, batch: int = 50) -> float:
    """Measured GFLOP/s of the policy's own matmuls at this batch size (jitted, float32)."""
    obs = jnp.zeros((batch, OBS))
    _members(policy, obs).block_until_ready()
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < 2.0:
        _members(policy, obs).block_until_ready()
        n += 1
    return n * batch * FLOP_PER_STEP / (time.perf_counter() - t0) / 1e9


def bench_mujoco(task, policy, n: int, horizon: int) -> float:
    seeds = np.arange(n)
    rollout_mujoco_policy(task, policy, seeds, 1)  # compile the policy call for this batch
    t0 = time.perf_counter()
    rollout_mujoco_policy(task, policy, seeds, horizon)
    return n * horizon / (time.perf_counter() - t0)


def bench_reference(task, policy, n: int, horizon: int) -> float:
    act = jax.jit(lambda p, c, o: p.act(c, o))
    act(policy, policy.init_carry(1), np.zeros((1, OBS), np.float32))  # compile first
    t0 = time.perf_counter()
    with BatchSim(task, 1, threads=1) as sim:
        for i in range(n):
            obs = sim.reset_seeds(np.array([i]))
            carry = policy.init_carry(1)
            for _ in range(horizon):
                carry, a = act(policy, carry, obs.astype(np.float32))
                obs = sim.step(np.asarray(a, np.float64))
    return n * horizon / (time.perf_counter() - t0)


def bench_mjx(task, policy, n: int, horizon: int) -> tuple[float, float]:
    fn = rollout_fn(task, horizon)
    q, m = task.init_states(np.arange(n))
    q, m = q.astype(np.float32), m.astype(np.float32)
    t0 = time.perf_counter()
    jax.block_until_ready(fn(policy, q, m))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    jax.block_until_ready(fn(policy, q, m))
    return n * horizon / (time.perf_counter() - t0), first


def compile_times(task_name: str, horizon: int) -> dict[str, float]:
    """Seconds to the first MJX result in a fresh process (imports included), through the
    evaluation path (exported rollout + persistent compilation cache): empty cache, then warm.
    """
    here = os.path.dirname(os.path.abspath(__file__))
    code = "\n".join(
        [
            "import time; t0 = time.perf_counter()",
            "from elicit_jax.runtime import configure; configure(mjx=True)",
            f"import sys; sys.path.insert(0, {here!r})",
            "import bench_rollouts as b, numpy as np, jax",
            "from elicit_jax.sim.rollout_mjx import rollout_mjx",
            f"rollout_mjx(b.make_task({task_name!r}), b.paper_policy(), np.arange(50), {horizon})",
            "print(time.perf_counter() - t0)",
        ]
    )
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, JAX_COMPILATION_CACHE_DIR=cache)
        for name in ("cold", "warm"):
            res = subprocess.run(
                [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
            )
            out[name] = float(res.stdout.strip().splitlines()[-1])
    return out


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(
        description="Rollout speed with the policy in the loop: MJX, C MuJoCo, reference."
    )
    ap.add_argument("--quick", action="store_true", help="Fewer steps (and sizes 16 50).")
    ap.add_argument("--json", help="Also write the results here.")
    ap.add_argument("--task", default="square-nut", help="Task to roll out.")
    ap.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        default=None,
        help="Rollout counts for the scaling table (default 16 50 200 1000; --quick: 16 50).",
    )
    ap.add_argument(
        "--scaling-horizon",
        type=int,
        default=10,
        help="Control steps per rollout in the scaling table (steps/s need no full horizon).",
    )
    ap.add_argument(
        "--rounds",
        type=int,
        default=5,
        help="Back-to-back (bound, C backend) pairs; the median pair is reported.",
    )
    ap.add_argument(
        "--no-compile-times",
        action="store_true",
        help="Skip the cold/warm MJX start measurement (two fresh processes).",
    )
    ap.add_argument("--robosuite", help="Compare the robosuite backend on this task instead.")
    ap.add_argument("--workers", type=int, default=0, help="robosuite workers (0: CPUs).")
    ap.add_argument("--rs-rollouts", type=int, default=6, help="Serial rollouts (robosuite).")
    ap.add_argument("--rs-horizon", type=int, default=100, help="Steps per rollout (robosuite).")
    ap.add_argument("--rs-rounds", type=int, default=3, help="Rounds of the three (robosuite).")
    return ap.parse_args(argv)


def main() -> None:
    args = parse_args()
    if args.robosuite:
        from bench_robosuite import main_robosuite

        main_robosuite(args)
        return
    task = make_task(args.task)
    sub = task.config.substeps
    policy = paper_policy()
    h_c, h_ref, h_mjx = (40, 10, 5) if args.quick else (100, 20, 10)
    h_scale = args.scaling_horizon
    h_scale_c = max(h_scale, h_c // 4)  # C set-up (MjData, reset) is timed too: not too short
    sizes = tuple(args.sizes or ((16, 50) if args.quick else (16, 50, 200, 1000)))
    res: dict = {
        "task": args.task,
        "threads": os.cpu_count(),
        "pjrt_nproc": os.environ.get("PJRT_NPROC"),
        "substeps": sub,
        "steps": {
            "mujoco": h_c,
            "reference": h_ref * 5,
            "mjx": h_mjx,
            "scaling_mjx": h_scale,
            "scaling_mujoco": h_scale_c,
        },
    }
    log("config", res)
    # The bound and the C backend move together with the machine's state: measure them in
    # back-to-back pairs and report the median pair (and every pair's fraction).
    pairs = []
    for _ in range(args.rounds):
        gflops = matmul_gflops(policy)
        pairs.append((gflops, bench_mujoco(task, policy, 50, h_c)))
        log("pair (matmul GFLOP/s, mujoco env-steps/s)", pairs[-1])
    bounds = [g * 1e9 / FLOP_PER_STEP for g, _ in pairs]
    fracs = [c / bound for (_, c), bound in zip(pairs, bounds, strict=True)]
    median = int(np.argsort(fracs)[len(fracs) // 2])
    res["matmul_gflops"], res["mujoco_50"] = pairs[median]
    res["bound_env_steps"] = bounds[median]
    res["mujoco_fraction_of_bound_rounds"] = fracs
    res["reference"] = bench_reference(task, policy, 3 if args.quick else 5, h_ref * 5)
    log("reference", res["reference"])
    res["mjx_50"], res["mjx_first_call_s"] = bench_mjx(task, policy, 50, h_mjx)
    log("mjx_50", res["mjx_50"])
    res["scaling"] = {}
    for n in sizes:
        mjx = res["mjx_50"] if (n, h_scale) == (50, h_mjx) else None
        res["scaling"][n] = {
            "mujoco": bench_mujoco(task, policy, n, h_scale_c),
            "mjx": mjx or bench_mjx(task, policy, n, h_scale)[0],
        }
        log(f"scaling {n}", res["scaling"][n])
    if not args.no_compile_times:
        res["compile"] = compile_times(args.task, h_mjx)
    report(res, sub)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1)


def log(name: str, value: object) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {name}: {value}", flush=True)


def report(res: dict, sub: int) -> None:
    bound = res["bound_env_steps"]
    steps = res["steps"]
    print(
        f"task: {res['task']}, {sub} physics steps per env-step; XLA CPU threads "
        f"PJRT_NPROC={res['pjrt_nproc']} on {res['threads']} CPUs"
    )
    print(
        f"control steps per rollout (not the full horizon): mjx {steps['mjx']}, mujoco "
        f"{steps['mujoco']}, reference {steps['reference']}; scaling table: mjx "
        f"{steps['scaling_mjx']}, mujoco {steps['scaling_mujoco']}"
    )
    print(f"policy: MLP 5 x (2 x 1024), {FLOP_PER_STEP / 1e6:.1f} MFLOP per env-step")
    print(
        f"matmul: {res['matmul_gflops']:.1f} GFLOP/s at batch 50 -> bound {bound:.0f} env-steps/s"
    )
    print(f"{'backend (50 rollouts)':28s} {'env-steps/s':>12s} {'physics/s':>12s} {'of bound':>9s}")
    for name, key in (("mjx", "mjx_50"), ("mujoco (C, threads)", "mujoco_50"),
                      ("reference (1 env, serial)", "reference")):  # fmt: skip
        v = res[key]
        print(f"{name:28s} {v:12.0f} {v * sub:12.0f} {v / bound:9.0%}")
    fracs = ", ".join(f"{f:.0%}" for f in res["mujoco_fraction_of_bound_rounds"])
    print(f"C backend of bound in each (bound, C) pair: {fracs}; median pair shown")
    print(f"C backend vs reference: {res['mujoco_50'] / res['reference']:.1f}x")
    if "compile" in res:
        print(
            f"MJX compile+first run: cold {res['compile']['cold']:.1f} s, warm (persistent "
            f"cache) {res['compile']['warm']:.1f} s"
        )
    print(
        f"{'rollouts':>8s} {'mujoco env-steps/s':>19s} {'mjx env-steps/s':>16s} "
        f"{'mjx ms/rollout-step':>20s}"
    )
    for n, r in res["scaling"].items():
        print(f"{n:8d} {r['mujoco']:19.0f} {r['mjx']:16.0f} {1e3 / r['mjx']:20.2f}")


if __name__ == "__main__":
    main()
