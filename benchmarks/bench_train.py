"""Training throughput: the JAX ensemble vs the same ensemble in PyTorch, member by member.

Both sides train K MLP members (Dense -> LayerNorm -> ReLU, dropout 0.5 between hidden layers,
tanh head, Adam, MSE, gradients clipped at norm 10 as in the original code) on the same
synthetic data with the same batch size; the JAX side is elicit-jax's own jitted training loop
(one compiled epoch: members one after another, minibatches in ``lax.scan``), the PyTorch side
trains one member after another as the original code does, in two forms:

* ``original``: the original code's loop (kanishkg/elicit ``src/algos/base_algo.py``): a
  ``DataLoader(shuffle=True)`` over a per-sample ``Dataset`` of (obs, action, weight), the
  weighted loss, ``clip_grad_norm_`` and ``loss.item()`` every step;
* ``lean``: the same model and optimiser fed by indexing pre-loaded tensors with a random
  permutation (no DataLoader, no per-step host sync) - the fastest plain PyTorch loop we wrote.
Throughput is dataset samples per second through the whole ensemble (each sample is seen by all
K members). Achieved GFLOP/s counts fwd + bwd as 3x the forward matmul FLOPs and is compared
with a plain fp32 matmul measured in the same run. Every ratio is taken within one of
``--rounds`` interleaved rounds and reported as median [min–max] over rounds. Targets (issue
#16), against the lean loop: >= 2x at cpu sizes; >= 1.5x and >= 70% of the JAX matmul's
GFLOP/s at paper sizes.

Usage:
    python benchmarks/bench_train.py [--seconds 3] [--rounds 5] [--out results/train.md]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

SIZES = {
    "paper": {"members": 5, "hidden": (1024, 1024), "obs": 23, "act": 7, "batch": 512, "n": 2048},
    "cpu": {"members": 5, "hidden": (256, 256), "obs": 23, "act": 7, "batch": 512, "n": 5120},
}
CLIP = 10.0
TORCH_STYLES = ("original", "lean")
# issue #16: against the lean loop (the stronger reference); the original loop is reported too
TARGETS = {"paper": {"ratio": 1.5, "matmul_frac": 0.7}, "cpu": {"ratio": 2.0}}


def flops_per_sample(s: dict) -> float:
    """fwd + bwd FLOPs of one sample through all members: 3 x 2 x (sum of layer in*out) x K."""
    dims = (s["obs"], *s["hidden"], s["act"])
    macs = sum(a * b for a, b in itertools.pairwise(dims))
    return 3.0 * 2.0 * macs * s["members"]


def make_data(s: dict, seed: int = 0):
    import numpy as np

    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(s["n"], s["obs"])).astype(np.float32)
    w = rng.normal(size=(s["obs"], s["act"])).astype(np.float32) * 0.3
    return obs, np.tanh(obs @ w).astype(np.float32)


def time_best(fn, seconds: float, min_reps: int = 2) -> float:
    """Best wall time of repeated ``fn()`` calls within about ``seconds``."""
    best, start, reps = float("inf"), time.perf_counter(), 0
    while reps < min_reps or time.perf_counter() - start < seconds:
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
        reps += 1
    return best


def jax_epoch(s: dict):
    """A compiled ``run()`` doing one epoch of elicit-jax's training loop (all members)."""
    import jax.numpy as jnp
    import numpy as np

    from elicit_jax.policy.kinds import make_module
    from elicit_jax.policy.loop import LoopSpec, init_states, make_chunk_fn

    obs, act = make_data(s)
    n = s["n"]
    spec = LoopSpec(
        kind="mlp",
        module=make_module("mlp", s["hidden"], s["act"], 0.5, 2),
        n_members=s["members"],
        obs_dim=s["obs"],
        batch_size=s["batch"],
        n_train=n,
        n_val=0,
        lr=1e-3,
        grad_clip=CLIP,
        bootstrap=False,
    )
    data = {
        "obs": jnp.asarray(obs),
        "action": jnp.asarray(act),
        "train_windows": jnp.arange(n, dtype=jnp.int32)[:, None],
        "train_mask": jnp.ones((n, 1)),
        "val_windows": jnp.zeros((0, 1), jnp.int32),
        "val_mask": jnp.zeros((0, 1)),
    }
    fn = make_chunk_fn(spec, 1)
    box = {"state": init_states(spec, (0,)), "epoch": 0}

    def run() -> None:
        box["state"], losses = fn(box["state"], data, jnp.asarray(box["epoch"], jnp.int32))
        box["epoch"] += 1
        np.asarray(losses[0])

    run()  # compile
    return run


def torch_epoch(s: dict, threads: int, style: str):
    """A warmed-up ``run()`` doing one epoch of each member in turn in PyTorch on ``threads``
    intra-op threads, in the ``original`` or ``lean`` style (module docstring)."""
    import torch
    from torch import nn
    from torch.utils.data import DataLoader, Dataset

    torch.manual_seed(0)
    obs, act = (torch.from_numpy(a) for a in make_data(s))

    def member() -> nn.Module:
        layers, d = [], s["obs"]
        for i, h in enumerate(s["hidden"]):
            if i > 0:
                layers.append(nn.Dropout(0.5))
            layers += [nn.Linear(d, h), nn.LayerNorm(h), nn.ReLU()]
            d = h
        return nn.Sequential(*layers, nn.Linear(d, s["act"]), nn.Tanh())

    class Buffer(Dataset):
        """The original's per-sample dataset: (obs, action, weight) by index."""

        def __init__(self) -> None:
            self.w = torch.ones(len(obs))

        def __len__(self) -> int:
            return len(obs)

        def __getitem__(self, i: int):
            return obs[i], act[i], self.w[i]

    nets = [member() for _ in range(s["members"])]
    opts = [torch.optim.Adam(m.parameters(), lr=1e-3) for m in nets]
    loader = DataLoader(Buffer(), batch_size=s["batch"], shuffle=True)

    def step(net: nn.Module, opt, o, a, w=None) -> torch.Tensor:
        opt.zero_grad()
        err = torch.sum((a - net(o)) ** 2, dim=1)
        loss = torch.mean(err if w is None else w * err)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), CLIP)
        opt.step()
        return loss

    def run() -> None:
        torch.set_num_threads(threads)
        for net, opt in zip(nets, opts, strict=True):
            net.train()
            if style == "original":
                for o, a, w in loader:
                    step(net, opt, o.float(), a.float(), w.float()).item()
            else:
                perm = torch.randperm(s["n"])
                for i in range(0, s["n"], s["batch"]):
                    idx = perm[i : i + s["batch"]]
                    step(net, opt, obs[idx], act[idx])

    run()
    return run


def interleaved(runs: dict, seconds: float, rounds: int) -> dict[str, list[float]]:
    """Each ``run``'s best time in each of ``rounds`` rounds (about ``seconds / rounds`` per
    run and round; the order reversed every other round), so ratios can be taken within a
    round while the machine's load drifts between rounds."""
    times: dict[str, list[float]] = {k: [] for k in runs}
    names = list(runs)
    for r in range(rounds):
        for name in names if r % 2 == 0 else names[::-1]:
            times[name].append(time_best(runs[name], seconds / rounds, min_reps=1))
    return times


def spread(values: list[float]) -> dict[str, float]:
    """Median and range of per-round values."""
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def matmul_runs(size: int = 4096) -> dict:
    """Warmed-up ``run()``s of a plain fp32 ``size^3`` matmul in JAX and in PyTorch."""
    import jax
    import jax.numpy as jnp
    import torch

    a = jax.random.normal(jax.random.key(0), (size, size), jnp.float32)
    mm = jax.jit(lambda x: x @ x)
    ta = torch.randn(size, size)
    runs = {"matmul_jax": lambda: mm(a).block_until_ready(), "matmul_torch": lambda: ta @ ta}
    for run in runs.values():
        run()
    return runs


def run_all(seconds: float, sizes: list[str], rounds: int) -> dict:
    import jax
    import torch

    threads = torch.get_num_threads()
    mm_runs = matmul_runs()
    mm_flops = 2.0 * 4096**3
    rows = {}
    for name in sizes:
        s = SIZES[name]
        runs = {"jax": jax_epoch(s)}
        for style in TORCH_STYLES:
            for n_threads in sorted({threads, 1}, reverse=True):
                runs[f"torch_{style}_{n_threads}t"] = torch_epoch(s, n_threads, style)
        times = interleaved({**runs, **mm_runs}, seconds * len(runs) / 2, rounds)
        sps = {k: [s["n"] / t for t in v] for k, v in times.items() if k in runs}
        mm = {k.removeprefix("matmul_"): [mm_flops / t / 1e9 for t in times[k]] for k in mm_runs}
        fps = flops_per_sample(s)
        jx = sps["jax"]
        torch_ref, ratios = {}, {}
        for style in TORCH_STYLES:
            keys = [k for k in runs if k.startswith(f"torch_{style}_")]
            fastest = max(keys, key=lambda k: statistics.median(sps[k]))
            torch_ref[style] = fastest
            ratios[style] = [a / b for a, b in zip(jx, sps[fastest], strict=True)]
        ratios["matmul"] = [a * fps / 1e9 / g for a, g in zip(jx, mm["jax"], strict=True)]
        rows[name] = {
            "sizes": s,
            "samples_per_s": {k: spread(v) for k, v in sps.items()},
            "torch_reference": torch_ref,
            "ratios": {k: spread(v) for k, v in ratios.items()},
            "ratio_rounds": ratios,
            "jax_gflops": spread([a * fps / 1e9 for a in jx]),
            "matmul_gflops_4096": {k: spread(v) for k, v in mm.items()},
        }
    return {
        "results": rows,
        "machine": {
            "cpus": os.cpu_count(),
            "load_avg_1m": os.getloadavg()[0],
            "platform": platform.platform(),
            "jax": jax.__version__,
            "torch": torch.__version__,
            "torch_threads": threads,
            "pjrt_nproc": os.environ.get("PJRT_NPROC", ""),
            "xla_flags": os.environ.get("XLA_FLAGS", ""),
            "rounds": rounds,
        },
    }


def _fmt(d: dict[str, float], f: str = "{:,.0f}", scale: float = 1.0) -> str:
    """``median [min–max]`` of a :func:`spread`."""
    m, lo, hi = (f.format(scale * d[k]) for k in ("median", "min", "max"))
    return f"{m} [{lo}–{hi}]"


def _verdict(median: float, rounds: list[float], target: float) -> str:
    won = sum(v >= target for v in rounds)
    if median >= target:
        return (
            "met (every round)"
            if won == len(rounds)
            else f"met on the median ({won}/{len(rounds)} rounds)"
        )
    return f"**not met** ({won}/{len(rounds)} rounds)"


def to_markdown(res: dict, command: str) -> str:
    m = res["machine"]
    lines = [
        "# Training throughput: the JAX ensemble vs PyTorch member by member",
        "",
        f"Machine: {m['cpus']} CPUs, load average {m['load_avg_1m']:.1f} at the end of the run "
        f"(shared machine), jax {m['jax']}, torch {m['torch']} (default {m['torch_threads']} "
        f"threads), PJRT_NPROC={m['pjrt_nproc']}, XLA_FLAGS=`{m['xla_flags']}`. "
        f"{m['rounds']} interleaved rounds; figures are median [min–max] over rounds, ratios "
        "are taken within a round.",
        "",
        "| sizes | K x hidden | batch | JAX samples/s | PyTorch original loop | "
        "PyTorch lean loop | JAX GFLOP/s | matmul GFLOP/s, JAX |",
        "|---|---|---|---:|---:|---:|---:|---:|",
    ]
    for name, r in res["results"].items():
        s, sps, ref = r["sizes"], r["samples_per_s"], r["torch_reference"]
        threads = {k: ref[k].rsplit("_", 1)[1].replace("t", " thr.") for k in ref}
        lines.append(
            f"| {name} | {s['members']} x {'x'.join(map(str, s['hidden']))} | {s['batch']} | "
            f"{_fmt(sps['jax'])} | {_fmt(sps[ref['original']])} ({threads['original']}) | "
            f"{_fmt(sps[ref['lean']])} ({threads['lean']}) | {_fmt(r['jax_gflops'], '{:.1f}')} | "
            f"{_fmt(r['matmul_gflops_4096']['jax'], '{:.1f}')} |"
        )
    lines += ["", "| sizes | ratio | measured | target | verdict |", "|---|---|---:|---:|---|"]
    for name, r in res["results"].items():
        t, rat, rr = TARGETS[name], r["ratios"], r["ratio_rounds"]
        lines.append(
            f"| {name} | JAX / PyTorch lean loop | {_fmt(rat['lean'], '{:.2f}x')} | "
            f">= {t['ratio']:g}x | {_verdict(rat['lean']['median'], rr['lean'], t['ratio'])} |"
        )
        if "matmul_frac" in t:
            lines.append(
                f"| {name} | JAX GFLOP/s / JAX matmul | {_fmt(rat['matmul'], '{:.0f}%', 100)} | "
                f">= {100 * t['matmul_frac']:.0f}% | "
                f"{_verdict(rat['matmul']['median'], rr['matmul'], t['matmul_frac'])} |"
            )
        else:
            lines.append(
                f"| {name} | JAX GFLOP/s / JAX matmul | {_fmt(rat['matmul'], '{:.0f}%', 100)} | | |"
            )
        lines.append(
            f"| {name} | JAX / PyTorch original loop | {_fmt(rat['original'], '{:.2f}x')} | | |"
        )
    lines += [
        "",
        "Samples/s = dataset samples per second through all K members (fwd + bwd + Adam), "
        "dropout 0.5, MSE, gradient clipping at 10; GFLOP/s = samples/s x 3 x forward matmul "
        "FLOPs. PyTorch original loop = the original code's DataLoader loop; lean loop = "
        "indexing pre-loaded tensors (see the script's docstring). Each PyTorch loop is timed "
        "with its default thread count and with 1 thread; the setting with the faster median "
        "is the reference. In each round every contender keeps its best epoch time of a short "
        "budget; the matmul (fp32 4096^3) is timed in the same rounds.",
        f"Command: `{command}`",
    ]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="timing budget per side")
    parser.add_argument("--sizes", default="paper,cpu", help="comma-separated: paper,cpu")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved timing rounds")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/train.md"))
    args = parser.parse_args()
    from elicit_jax.runtime import configure

    configure()
    res = run_all(args.seconds, args.sizes.split(","), args.rounds)
    text = to_markdown(res, " ".join(["python", *sys.argv]))
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    args.out.with_suffix(".json").write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
