"""Live M at control rate: latency of one step's compatibility, ours vs the original PyTorch call.

During a demonstration the live indicator needs M of ONE state-action pair per control step.
Two contenders score the same pairs with the same weights (our Flax ensemble copied into
PyTorch):

* **ours**: :class:`elicit_jax.elicit.live.LiveScorer` — what a session calls each step: one
  compiled single-state scorer (policy and thresholds are arguments, so nothing recompiles),
  numpy in, Python floats out (the device-to-host copy included);
* **torch, original**: the original code's per-step call (kanishkg/elicit
  ``src/web_utils/algorithm_wrapper.py``: ``get_compatibility(obs, a, type="entropy")`` then
  ``type="likelihood"``, each a Python loop over the 5 members on one state under
  ``torch.no_grad``, ``.item()`` on each), with the same observation normalisation. Run
  with PyTorch's faster thread setting (its default or 1 thread, chosen on 100 steps).

Ours uses the original definitions (member-average likelihood, sample std) so the two are
checked to agree pair by pair. Sizes: **paper** (5 × 2 × 1024) and **cpu** (5 × 2 × 256),
23-D observations, 7-D actions. Latencies are pooled over interleaved rounds (ours, torch,
ours, ...), so load from other processes hits both alike; p50, p99 and the mean of the wall
time are reported, with the process's CPU time per step (the work, which other jobs on a
shared machine do not inflate) and the machine's load average before and after.

Targets: p99 ≤ 2 ms at paper size, and ≥ 3× faster than the PyTorch per-step call.

Run: ``python benchmarks/bench_live.py [--quick] [--out benchmarks/results/live.md]`` (needs
the ``bench`` extra: ``pip install 'elicit-jax[bench]'``).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import time
from pathlib import Path

from bench_score import ACT, OBS, bench_policy, torch_models
from machine import busy_cores, busy_text

SIZES = {"paper": 1024, "cpu": 256}


def _args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--steps", type=int, default=500, help="steps per contender and round")
    p.add_argument("--rounds", type=int, default=6, help="interleaved rounds")
    p.add_argument("--sizes", default="paper,cpu", help="paper and/or cpu")
    p.add_argument("--quick", action="store_true", help="fewer steps and rounds")
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/live.md"))
    a = p.parse_args()
    if a.quick:
        a.steps, a.rounds = 200, 3
    return a


def _torch_step(models, mean, std, obs, act, lim=1.0):
    """The original per-step call: novelty then likelihood, a member loop each, ``.item()``."""
    import torch

    x = ((obs - mean) / std).unsqueeze(0)
    with torch.no_grad():
        preds = [m(x).detach() for m in models]
        nu = torch.mean(torch.std(torch.stack(preds), dim=0)).item()
    with torch.no_grad():
        errs = []
        for m in models:
            a = torch.clamp(act, min=-lim, max=lim)
            pred = torch.clamp(m(x).detach(), min=-lim, max=lim)
            errs.append(((pred - a) ** 2).mean(dim=-1))
        ell = torch.mean(torch.stack(errs)).item()
    return ell, nu


def _percentiles(ms):
    import numpy as np

    a = np.asarray(ms)
    return {
        "p50": float(np.percentile(a, 50)),
        "p99": float(np.percentile(a, 99)),
        "mean": float(a.mean()),
        "n": len(a),
    }


def bench_size(hidden: int, steps: int, rounds: int) -> dict:
    import numpy as np
    import torch

    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.elicit.live import LiveScorer

    rng = np.random.default_rng(0)
    obs = rng.normal(size=(steps, OBS)).astype(np.float32)
    act = rng.uniform(-1, 1, size=(steps, ACT)).astype(np.float32)
    mean, std = obs.mean(0), obs.std(0) + 0.5
    policy = bench_policy(hidden, mean, std)
    scorer = LiveScorer(
        ScoreConfig.from_preset("square-nut", likelihood="member-average", ddof=1), policy
    )
    models = torch_models(policy)
    tm, ts = torch.from_numpy(mean), torch.from_numpy(std)
    obs_t, act_t = torch.from_numpy(obs), torch.from_numpy(act)
    t = time.perf_counter()
    scorer.score(policy, obs[0], act[0])
    compile_s = time.perf_counter() - t
    err = 0.0
    for i in range(20):  # same pairs, same definitions: the two agree
        s = scorer.score(policy, obs[i], act[i])
        ell, nu = _torch_step(models, tm, ts, obs_t[i], act_t[i])
        err = max(err, abs(s.likelihood - ell), abs(s.novelty - nu))
    default_threads = torch.get_num_threads()
    calib = {}
    for threads in sorted({default_threads, 1}):  # pick PyTorch's faster thread setting
        torch.set_num_threads(threads)
        ms = []
        for i in range(min(steps, 100)):
            t = time.perf_counter()
            _torch_step(models, tm, ts, obs_t[i], act_t[i])
            ms.append(1e3 * (time.perf_counter() - t))
        calib[threads] = _percentiles(ms)["p50"]
    threads = min(calib, key=calib.get)
    torch.set_num_threads(threads)
    key = f"torch ({threads} thread{'s' if threads > 1 else ''})"
    lat = {"ours": [], key: []}
    cpu = {"ours": [], key: []}

    def timed(name, fn, i):
        t, c = time.perf_counter(), time.process_time()
        fn(i)
        lat[name].append(1e3 * (time.perf_counter() - t))
        cpu[name].append(1e3 * (time.process_time() - c))

    for _ in range(rounds):
        for i in range(steps):
            timed("ours", lambda i: scorer.score(policy, obs[i], act[i]), i)
        for i in range(steps):
            timed(key, lambda i: _torch_step(models, tm, ts, obs_t[i], act_t[i]), i)
    torch.set_num_threads(default_threads)
    assert scorer.traces == 1, "the live scorer recompiled"
    stats = {k: _percentiles(v) for k, v in lat.items()}
    cpu_stats = {k: _percentiles(v) for k, v in cpu.items()}
    best = key
    return {
        "torch_threads_p50": {str(k): v for k, v in calib.items()},
        "hidden": hidden,
        "compile_s": compile_s,
        "max_abs_diff": err,
        "stats": stats,
        "cpu": cpu_stats,
        "torch_best": best,
        "ratio_p50": stats[best]["p50"] / stats["ours"]["p50"],
        "ratio_p99": stats[best]["p99"] / stats["ours"]["p99"],
    }


def _report(results: dict, load: tuple, seconds: float, busy: float | None = None) -> str:
    lines = [
        "# Live M per control step: elicit-jax vs the original PyTorch per-step call",
        "",
        f"{dt.datetime.now().isoformat(timespec='minutes')}, {platform.machine()}, "
        f"{os.cpu_count()} CPUs; load average (1 min) {load[0]:.2f} before, {load[1]:.2f} "
        f"after (both include recent work, the after one this benchmark's); {busy_text(busy)}; "
        f"{seconds:.0f} s.",
        "",
        "| size | contender | p50 ms | p99 ms | mean ms | CPU ms p50 | CPU ms p99 | steps |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, r in results.items():
        for k, s in r["stats"].items():
            c = r["cpu"][k]
            lines.append(
                f"| {name} (5 × 2 × {r['hidden']}) | {k} | {s['p50']:.3f} | {s['p99']:.3f} | "
                f"{s['mean']:.3f} | {c['p50']:.3f} | {c['p99']:.3f} | {s['n']} |"
            )
    lines += [
        "",
        "| size | ours p99 (wall) | p99 ≤ 2 ms | speed-up: wall p50 | wall p99 | CPU p50 "
        "| ≥ 3× (wall p50) |",
        "|---|---:|---|---:|---:|---:|---|",
    ]
    for name, r in results.items():
        p99 = r["stats"]["ours"]["p99"]
        ok = ("met" if p99 <= 2.0 else "NOT met") if name == "paper" else "-"
        cpu_ratio = r["cpu"][r["torch_best"]]["p50"] / r["cpu"]["ours"]["p50"]
        lines.append(
            f"| {name} | {p99:.3f} ms | {ok} | {r['ratio_p50']:.1f}× | {r['ratio_p99']:.1f}× | "
            f"{cpu_ratio:.1f}× | {'met' if r['ratio_p50'] >= 3 else 'NOT met'} |"
        )
    lines += [
        "",
        "Ours vs torch agree on ℓ and ν to "
        + ", ".join(f"{r['max_abs_diff']:.1e} ({n})" for n, r in results.items())
        + "; first call (compile, or the persistent cache) "
        + ", ".join(f"{r['compile_s']:.2f} s ({n})" for n, r in results.items())
        + ". PyTorch ran with its faster thread setting, chosen on 100 calibration steps (p50 "
        + "; ".join(
            f"{n}: "
            + ", ".join(f"{t} thread(s) {v:.2f} ms" for t, v in r["torch_threads_p50"].items())
            for n, r in results.items()
        )
        + "). Wall time is what a control loop waits; CPU ms is the process's CPU time per "
        "step (all threads), the work itself, which other jobs on the machine do not inflate.",
    ]
    return "\n".join(lines) + "\n"


def main() -> None:
    from elicit_jax.runtime import configure

    configure()
    a = _args()
    busy = busy_cores()
    t0 = time.time()
    load0 = os.getloadavg()[0]
    results = {}
    for name in a.sizes.split(","):
        results[name] = bench_size(SIZES[name], a.steps, a.rounds)
        r = results[name]
        print(
            f"{name}: ours p50 {r['stats']['ours']['p50']:.3f} ms p99 "
            f"{r['stats']['ours']['p99']:.3f} ms; {r['torch_best']} p50 "
            f"{r['stats'][r['torch_best']]['p50']:.3f} ms p99 "
            f"{r['stats'][r['torch_best']]['p99']:.3f} ms; speed-up {r['ratio_p50']:.1f}x "
            f"(p50) {r['ratio_p99']:.1f}x (p99)"
        )
    text = _report(results, (load0, os.getloadavg()[0]), time.time() - t0, busy)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(text)
    a.out.with_suffix(".json").write_text(json.dumps(results, indent=1) + "\n")
    print(text)


if __name__ == "__main__":
    main()
