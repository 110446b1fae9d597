"""Training throughput: the vmapped JAX ensemble vs the same ensemble in PyTorch, member by member.

Both sides train K MLP members (Dense -> LayerNorm -> ReLU, dropout 0.5 between hidden layers,
tanh head, Adam, MSE, gradients clipped at norm 10 as in the original code) on the same
synthetic data with the same batch size; the JAX side is elicit-jax's own jitted training loop
(all members in one vmapped step, epochs and minibatches in ``lax.scan``), the PyTorch side
trains one member after another as the original code does, in two forms:

* ``original``: the original code's loop (kanishkg/elicit ``src/algos/base_algo.py``): a
  ``DataLoader(shuffle=True)`` over a per-sample ``Dataset`` of (obs, action, weight), the
  weighted loss, ``clip_grad_norm_`` and ``loss.item()`` every step;
* ``lean``: the same model and optimiser fed by indexing pre-loaded tensors with a random
  permutation (no DataLoader, no per-step host sync) - the fastest plain PyTorch loop we wrote.
Throughput is dataset samples per second through the whole ensemble (each sample is seen by all
K members). Achieved GFLOP/s counts fwd + bwd as 3x the forward matmul FLOPs and is compared
with a plain fp32 matmul measured in the same run.

Usage:
    python benchmarks/bench_train.py [--seconds 3] [--out benchmarks/results/train.md]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import time
from pathlib import Path

SIZES = {
    "paper": {"members": 5, "hidden": (1024, 1024), "obs": 23, "act": 7, "batch": 512, "n": 2048},
    "cpu": {"members": 5, "hidden": (256, 256), "obs": 23, "act": 7, "batch": 512, "n": 5120},
}
CLIP = 10.0
TORCH_STYLES = ("original", "lean")
TARGETS = {"paper": {"ratio": 1.0, "matmul_frac": 0.5}, "cpu": {"ratio": 2.0}}


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

    from elicit_jax.policy import models
    from elicit_jax.policy.loop import LoopSpec, init_states, make_chunk_fn

    obs, act = make_data(s)
    n = s["n"]
    spec = LoopSpec(
        kind="mlp",
        module=models.make_module("mlp", s["hidden"], s["act"], 0.5, 2),
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


def interleaved(runs: dict, seconds: float, rounds: int = 3) -> dict[str, float]:
    """Best time of each ``run`` over alternating rounds (the machine's load drifts)."""
    best = dict.fromkeys(runs, float("inf"))
    for _ in range(rounds):
        for name, run in runs.items():
            best[name] = min(best[name], time_best(run, seconds / rounds, min_reps=1))
    return best


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


def run_all(seconds: float, sizes: list[str]) -> dict:
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
        trainers = list(runs)
        best = interleaved({**runs, **mm_runs}, seconds * len(runs) / 2)
        mm = {k.removeprefix("matmul_"): mm_flops / best.pop(k) / 1e9 for k in mm_runs}
        jx = s["n"] / best["jax"]
        fps = flops_per_sample(s)
        torch_best = {}
        for style in TORCH_STYLES:
            keys = [k for k in trainers if k.startswith(f"torch_{style}_")]
            fastest = min(keys, key=best.__getitem__)
            torch_best[style] = {"setting": fastest, "samples_per_s": s["n"] / best[fastest]}
        rows[name] = {
            "sizes": s,
            "jax_samples_per_s": jx,
            "torch": torch_best,
            "torch_samples_per_s_by_setting": {
                k: s["n"] / v for k, v in best.items() if k != "jax"
            },
            "ratio": {k: jx / v["samples_per_s"] for k, v in torch_best.items()},
            "jax_gflops": jx * fps / 1e9,
            "jax_matmul_frac": jx * fps / 1e9 / mm["jax"],
            "jax_best_matmul_frac": jx * fps / 1e9 / max(mm.values()),
            "matmul_gflops_4096": mm,
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
            "xla_flags": os.environ.get("XLA_FLAGS", ""),
        },
    }


def to_markdown(res: dict) -> str:
    m = res["machine"]
    lines = [
        "# Training throughput: vmapped JAX ensemble vs PyTorch member by member",
        "",
        f"Machine: {m['cpus']} CPUs, load average {m['load_avg_1m']:.1f} at the end of the run "
        f"(shared machine), jax {m['jax']}, torch {m['torch']} ({m['torch_threads']} threads), "
        f"XLA_FLAGS=`{m['xla_flags']}`.",
        "",
        "| sizes | K x hidden | batch | JAX samples/s | PyTorch original loop | ratio | "
        "PyTorch lean loop | ratio | JAX GFLOP/s | matmul GFLOP/s (JAX / torch) | "
        "% of JAX matmul | % of best matmul | target |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in res["results"].items():
        s = r["sizes"]
        t = TARGETS[name]
        target = f">= {t['ratio']:g}x"
        if "matmul_frac" in t:
            target += f", >= {100 * t['matmul_frac']:.0f}% matmul"
        pt, ratio = r["torch"], r["ratio"]
        lines.append(
            f"| {name} | {s['members']} x {'x'.join(map(str, s['hidden']))} | {s['batch']} | "
            f"{r['jax_samples_per_s']:,.0f} | "
            f"{pt['original']['samples_per_s']:,.0f} | {ratio['original']:.2f}x | "
            f"{pt['lean']['samples_per_s']:,.0f} | {ratio['lean']:.2f}x | "
            f"{r['jax_gflops']:.1f} | "
            f"{r['matmul_gflops_4096']['jax']:.1f} / {r['matmul_gflops_4096']['torch']:.1f} | "
            f"{100 * r['jax_matmul_frac']:.0f}% | "
            f"{100 * r['jax_best_matmul_frac']:.0f}% | "
            f"{target} |"
        )
    lines += [
        "",
        "Samples/s = dataset samples per second through all K members (fwd + bwd + Adam), "
        "dropout 0.5, MSE, gradient clipping at 10; GFLOP/s = samples/s x 3 x forward matmul "
        "FLOPs. PyTorch original loop = the original code's DataLoader loop; lean loop = "
        "indexing pre-loaded tensors (see the script's docstring). Each PyTorch loop is timed "
        "with its default thread count and with 1 thread; the faster is reported. "
        "Each side's best epoch time over interleaved rounds is used. The matmul (fp32 "
        "4096^3) is timed in the same interleaved rounds as each row.",
        "Command: `python benchmarks/bench_train.py`",
    ]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="timing budget per side")
    parser.add_argument("--sizes", default="paper,cpu", help="comma-separated: paper,cpu")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/train.md"))
    args = parser.parse_args()
    from elicit_jax.runtime import configure

    configure()
    res = run_all(args.seconds, args.sizes.split(","))
    text = to_markdown(res)
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    args.out.with_suffix(".json").write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
