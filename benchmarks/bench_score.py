"""Scoring throughput: our chunked, jitted scorer vs the strongest PyTorch loops we wrote.

Paper sizes: an ensemble of 5 MLPs (2 hidden layers of 1024, LayerNorm, ReLU, tanh head),
23-D observations, 7-D actions, demonstrations of 90 steps. The same pairs are scored with the
same weights (our Flax parameters copied into torch) by:

* ``ours``: :func:`elicit_jax.compat.score.score_demos` at several chunk sizes (compile time
  measured separately and excluded), and on ONE 90-step episode per call (a small call: live
  feedback, per-episode scoring);
* ``ours, streamed``: ``score_file`` Parquet -> Parquet (what ``elicit-jax score`` does);
* ``torch per-demo``: the original code's approach (kanishkg/elicit ``src/util/util.py:
  get_compatibility`` calling ``src/models/ensemble.py: Ensemble.get_compatibility``), called
  once per 90-step demonstration (CPU, ``torch.no_grad``): one pass over the 5 members for the
  likelihood (member-average of clamped squared errors), a second for the novelty (unbiased
  std across members), then M;
* ``torch per-demo, one pass``: the stronger reference: both measures from one member loop;
* ``torch batched``: the original two-pass loop on large batches (``--torch-batch`` pairs).

Every PyTorch loop runs with PyTorch's default thread count and with 1 thread; the faster
setting (median over rounds) is the reference. Ours uses the original code's definitions
(``likelihood="member-average"``, ``ddof=1``) so the numbers compare pair by pair. A plain fp32
matmul (``--matmul-n``³) in JAX and in torch gives the attainable GFLOP/s (best of 5 calls per
round). FLOPs per pair = 5 members × 2 × (23·1024 + 1024·1024 + 1024·7) ≈ 10.8 MFLOP.

The contenders are interleaved in each of ``--rounds`` rounds (the order reversed every other
round); every ratio is taken within a round and reported as the median over rounds with its
range, so load that drifts between rounds cancels out. Targets (issue #16): best chunk
>= 1.2x the one-pass per-demo loop, >= 1.5x the batched loop, >= 70% of the JAX matmul;
chunk 1024 >= 80% of the best chunk; one 90-step episode in <= 2x its FLOP time at the
matmul's speed.

Run: ``.venv/bin/python benchmarks/bench_score.py [--quick] [--out results/score.md]``
(needs the ``bench`` extra: ``pip install 'elicit-jax[bench]'``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

OBS, ACT, K, HIDDEN, T = 23, 7, 5, 1024, 90
FLOP_PER_PAIR = K * 2 * (OBS * HIDDEN + HIDDEN * HIDDEN + HIDDEN * ACT)


def _args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--demos", type=int, default=100, help="90-step demos scored by ours/batched")
    p.add_argument("--per-demo", type=int, default=20, help="demos scored by the per-demo loop")
    p.add_argument("--chunks", default="1024,4096,8192", help="our chunk sizes to try")
    p.add_argument("--torch-batch", type=int, default=8192, help="pairs per batched torch call")
    p.add_argument("--matmul-n", type=int, default=2048, help="size of the reference matmul")
    p.add_argument("--rounds", type=int, default=7, help="interleaved timing rounds")
    p.add_argument("--quick", action="store_true", help="fewer demos and rounds")
    p.add_argument("--out", type=Path, default=None, help="write a Markdown report (+ .json)")
    a = p.parse_args()
    if a.quick:
        a.demos, a.per_demo, a.rounds = 60, 15, 5
    return a


def _cfg(chunk: int):
    """Our scorer with the original code's definitions, at a chunk size."""
    from elicit_jax.compat.measures import ScoreConfig

    return ScoreConfig(likelihood="member-average", ddof=1, chunk_size=chunk)


TARGETS = {
    "one_pass": 1.2,  # best chunk / torch per-demo one-pass loop
    "batched": 1.5,  # best chunk / torch batched loop
    "matmul": 0.70,  # best chunk GFLOP/s / JAX matmul GFLOP/s
    "chunk1024": 0.80,  # chunk 1024 / best chunk
    "episode": 2.0,  # one 90-step episode's time / its FLOP time at the matmul's speed
}


def _best_of(fn: Callable[[], object], calls: int) -> float:
    """Best wall time of ``calls`` back-to-back calls."""
    best = float("inf")
    for _ in range(calls):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def interleaved(
    jobs: dict[str, tuple[Callable[[], object], int]], rounds: int
) -> dict[str, list[float]]:
    """Seconds of every job in every round: ``{name: [s_round0, s_round1, ...]}``.

    Jobs are ``name -> (fn, calls)``; a job's time in a round is its best of ``calls``
    back-to-back calls (short calls need several). All jobs run once per round, in reverse
    order every other round, so drifting load hits every job alike.
    """
    times: dict[str, list[float]] = {k: [] for k in jobs}
    names = list(jobs)
    for r in range(rounds):
        for name in names if r % 2 == 0 else names[::-1]:
            fn, calls = jobs[name]
            times[name].append(_best_of(fn, calls))
    return times


def spread(values: list[float]) -> dict[str, float]:
    """Median and range of per-round values."""
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def bench_policy(hidden: int, mean=None, std=None, dropout: float = 0.5):
    """The benchmarked policy: the paper's ensemble of K MLPs with two ``hidden``-unit layers
    on OBS-dim observations (normalized by ``mean``/``std`` when given), seed 0."""
    import jax

    from elicit_jax.policy.base import init_policy

    return init_policy(
        jax.random.key(0),
        kind="mlp",
        obs_dim=OBS,
        action_dim=ACT,
        n_members=K,
        hidden=(hidden, hidden),
        dropout=dropout,
        obs_mean=mean,
        obs_std=std,
    )


def _torch_models(policy):
    """The policy's members as PyTorch modules (same weights; sizes read from the params)."""
    import numpy as np
    import torch
    from torch import nn

    params = policy.params
    trunk = params["Trunk_0"]
    n_layers = sum(1 for k in trunk if k.startswith("Dense_"))
    models = []
    for k in range(np.asarray(params["Dense_0"]["kernel"]).shape[0]):
        layers = []
        for i in range(n_layers):
            dense, norm = trunk[f"Dense_{i}"], trunk[f"LayerNorm_{i}"]
            lin = nn.Linear(*np.asarray(dense["kernel"][k]).shape)
            lin.weight.data = torch.from_numpy(np.asarray(dense["kernel"][k]).T.copy())
            lin.bias.data = torch.from_numpy(np.asarray(dense["bias"][k]).copy())
            ln = nn.LayerNorm(lin.out_features, eps=1e-6)
            ln.weight.data = torch.from_numpy(np.asarray(norm["scale"][k]).copy())
            ln.bias.data = torch.from_numpy(np.asarray(norm["bias"][k]).copy())
            layers += [lin, ln, nn.ReLU()] + ([nn.Dropout(0.5)] if i < n_layers - 1 else [])
        head = nn.Linear(*np.asarray(params["Dense_0"]["kernel"][k]).shape)
        head.weight.data = torch.from_numpy(np.asarray(params["Dense_0"]["kernel"][k]).T.copy())
        head.bias.data = torch.from_numpy(np.asarray(params["Dense_0"]["bias"][k]).copy())
        models.append(nn.Sequential(*layers, head, nn.Tanh()).eval())
    return models


def _torch_score(models, mean, std, obs, act, lam=0.4, eta=0.05, lim=1.0):
    """The original code's scoring of one call: a member loop for the likelihood (clamped,
    member-average), a second member loop for the novelty (unbiased std), then M."""
    import torch

    with torch.no_grad():
        x = (obs - mean) / std
        errs = []
        for m in models:
            a = torch.clamp(act, min=-lim, max=lim)
            pred = torch.clamp(m(x), min=-lim, max=lim)
            errs.append(((pred - a) ** 2).mean(dim=-1))
        ell = torch.mean(torch.stack(errs, dim=0), dim=0)
        nu = torch.std(torch.stack([m(x) for m in models], dim=0), dim=0).mean(dim=-1)
        m = torch.where(nu < eta, 1 - torch.clamp(ell / lam, max=1.0), torch.ones_like(ell))
    return ell, nu, m


def _torch_score_one_pass(models, mean, std, obs, act, lam=0.4, eta=0.05, lim=1.0):
    """Like :func:`_torch_score` with both measures from one member loop."""
    import torch

    with torch.no_grad():
        x = (obs - mean) / std
        preds = torch.clamp(torch.stack([m(x) for m in models]), min=-lim, max=lim)
        ell = ((preds - torch.clamp(act, min=-lim, max=lim)) ** 2).mean(-1).mean(0)
        nu = preds.std(0).mean(-1)
        m = torch.where(nu < eta, 1 - torch.clamp(ell / lam, max=1.0), torch.ones_like(ell))
    return ell, nu, m


def main() -> None:
    from elicit_jax.runtime import configure

    configure()
    import jax
    import jax.numpy as jnp
    import numpy as np
    import torch

    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.compat.score import score_demos
    from elicit_jax.compat.score_file import score_file
    from elicit_jax.data.demos import from_episodes, write_demos
    from elicit_jax.policy.base import normalization_stats

    a = _args()
    rng = np.random.default_rng(0)
    eps = [
        {
            "obs": rng.normal(size=(T, OBS)).astype(np.float32),
            "action": rng.uniform(-1, 1, size=(T, ACT)).astype(np.float32),
        }
        for _ in range(a.demos)
    ]
    demos = from_episodes(eps, operators="op")
    episode = from_episodes(eps[:1], operators="op")
    mean, std = normalization_stats(demos.obs)
    policy = bench_policy(HIDDEN, mean, std)
    n_pairs = demos.n_steps
    n = a.matmul_n
    xa = jax.random.normal(jax.random.key(1), (n, n), jnp.float32)
    mm = jax.jit(lambda x: x @ x)
    mm(xa).block_until_ready()
    xt = torch.randn(n, n)

    # --- compile ours at each chunk size (timed separately); copy the weights into torch ---
    chunks = [int(x) for x in a.chunks.split(",")]
    compile_s, ref = {}, None
    for c in chunks:
        t = time.perf_counter()
        ref = score_demos(policy, demos, _cfg(c))
        compile_s[c] = time.perf_counter() - t
    stream_chunk = ScoreConfig().chunk_size
    score_demos(policy, episode, _cfg(stream_chunk))
    models = _torch_models(policy)
    tmean, tstd = torch.from_numpy(np.asarray(mean)), torch.from_numpy(np.asarray(std))
    obs_t, act_t = torch.from_numpy(demos.obs), torch.from_numpy(demos.action)
    ell_t, nu_t, _ = _torch_score(models, tmean, tstd, obs_t, act_t)
    err = max(
        float(np.abs(ell_t.numpy() - ref["likelihood"]).max()),
        float(np.abs(nu_t.numpy() - ref["novelty"]).max()),
    )

    def torch_loop(fn, size: int, n_rows: int, threads: int) -> Callable[[], None]:
        def run() -> None:
            torch.set_num_threads(threads)
            for s in range(0, n_rows, size):
                fn(models, tmean, tstd, obs_t[s : s + size], act_t[s : s + size])

        return run

    tmp = Path(tempfile.mkdtemp(prefix="bench_score_"))
    write_demos(tmp / "demos.parquet", demos)

    def streamed() -> None:
        cfg = _cfg(stream_chunk)
        score_file(policy, tmp / "demos.parquet", tmp / "scores.parquet", cfg)

    streamed()
    default_threads = torch.get_num_threads()
    settings = sorted({default_threads, 1}, reverse=True)
    refs = {
        "per_demo": (_torch_score, T, a.per_demo * T),
        "one_pass": (_torch_score_one_pass, T, a.per_demo * T),
        "batched": (_torch_score, a.torch_batch, n_pairs),
    }
    jobs: dict[str, tuple[Callable[[], object], int]] = {
        f"ours{c}": ((lambda c=c: score_demos(policy, demos, _cfg(c))), 1) for c in chunks
    }
    jobs["episode"] = (lambda: score_demos(policy, episode, _cfg(stream_chunk)), 5)
    jobs["streamed"] = (streamed, 1)
    for name, (fn, size, rows) in refs.items():
        for th in settings:
            jobs[f"{name}_{th}t"] = (torch_loop(fn, size, rows, th), 1)
            jobs[f"{name}_{th}t"][0]()  # warm up
    torch.set_num_threads(default_threads)
    jobs["jax_mm"] = (lambda: mm(xa).block_until_ready(), 5)
    jobs["torch_mm"] = (lambda: torch.mm(xt, xt), 5)
    jobs["torch_mm"][0]()
    secs = interleaved(jobs, a.rounds)
    shutil.rmtree(tmp, ignore_errors=True)

    # --- per-round figures and ratios ---
    pps = {f"ours{c}": [n_pairs / t for t in secs[f"ours{c}"]] for c in chunks}
    pps["streamed"] = [n_pairs / t for t in secs["streamed"]]
    for name, (_, _, rows) in refs.items():
        for th in settings:
            pps[f"{name}_{th}t"] = [rows / t for t in secs[f"{name}_{th}t"]]
    ref_setting = {
        name: max(settings, key=lambda th, name=name: statistics.median(pps[f"{name}_{th}t"]))
        for name in refs
    }
    gflops = {k: [2 * n**3 / t / 1e9 for t in secs[k]] for k in ("jax_mm", "torch_mm")}
    best_c = max(chunks, key=lambda c: statistics.median(pps[f"ours{c}"]))
    best = pps[f"ours{best_c}"]
    per_round = {
        name: [o / r for o, r in zip(best, pps[f"{name}_{ref_setting[name]}t"], strict=True)]
        for name in refs
    }
    per_round["matmul"] = [
        o * FLOP_PER_PAIR / 1e9 / g for o, g in zip(best, gflops["jax_mm"], strict=True)
    ]
    if 1024 in chunks:
        per_round["chunk1024"] = [o / b for o, b in zip(pps["ours1024"], best, strict=True)]
    flop_s = [T * FLOP_PER_PAIR / (g * 1e9) for g in gflops["jax_mm"]]
    per_round["episode"] = [e / f for e, f in zip(secs["episode"], flop_s, strict=True)]
    result = {
        "pairs_per_s": {k: spread(v) for k, v in pps.items()},
        "matmul_gflops": {k: spread(v) for k, v in gflops.items()},
        "episode_ms": spread([1e3 * t for t in secs["episode"]]),
        "episode_flop_ms": spread([1e3 * f for f in flop_s]),
        "ratios": {k: spread(v) for k, v in per_round.items()},
        "ratio_rounds": per_round,
        "reference_threads": ref_setting,
        "best_chunk": best_c,
        "compile_s": compile_s,
        "max_abs_diff_vs_torch": err,
        "machine": {
            "cpus": os.cpu_count(),
            "load_avg_1m_end": os.getloadavg()[0],
            "jax": jax.__version__,
            "torch": torch.__version__,
            "torch_default_threads": default_threads,
            "PJRT_NPROC": os.environ.get("PJRT_NPROC", ""),
            "XLA_FLAGS": os.environ.get("XLA_FLAGS", ""),
        },
        "args": {k: str(v) for k, v in vars(a).items()},
    }
    text = to_markdown(result, a, n_pairs, stream_chunk)
    print(text)
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(text)
        a.out.with_suffix(".json").write_text(json.dumps(result, indent=1) + "\n")


def _fmt(d: dict[str, float], f: str = "{:,.0f}", scale: float = 1.0) -> str:
    """``median [min–max]`` of a :func:`spread`."""
    m, lo, hi = (f.format(scale * d[k]) for k in ("median", "min", "max"))
    return f"{m} [{lo}–{hi}]"


def _verdict(d: dict[str, float], rounds: list[float], target: float, below: bool) -> str:
    ok = [v <= target if below else v >= target for v in rounds]
    med = d["median"] <= target if below else d["median"] >= target
    if med and all(ok):
        return "met (every round)"
    if med:
        return f"met on the median ({sum(ok)}/{len(ok)} rounds)"
    return f"**not met** ({sum(ok)}/{len(ok)} rounds)"


def to_markdown(res: dict, a: argparse.Namespace, n_pairs: int, stream_chunk: int) -> str:
    m, p, r = res["machine"], res["pairs_per_s"], res["ratios"]
    th = res["reference_threads"]
    rows = [
        (f"ours, chunk {c}", p[f"ours{c}"], f"compile+first call {res['compile_s'][c]:.1f} s")
        for c in sorted(res["compile_s"])
    ]
    rows.append(
        (
            f"ours, streamed Parquet -> Parquet (score_file, chunk {stream_chunk})",
            p["streamed"],
            "includes reading, writing, episode summary",
        )
    )
    names = {
        "per_demo": f"torch per-demo loop ({T}-step demos), the original code",
        "one_pass": f"torch per-demo, one pass ({T}-step demos)",
        "batched": f"torch batched loop ({a.torch_batch} pairs/call)",
    }
    for key, label in names.items():
        for t in sorted({int(k.split("_")[-1][:-1]) for k in p if k.startswith(key + "_")}):
            mark = " **(reference)**" if t == th[key] else ""
            rows.append((f"{label}, {t} thread{'s' if t > 1 else ''}{mark}", p[f"{key}_{t}t"], ""))
    gf = FLOP_PER_PAIR / 1e9
    lines = [
        "# Scoring throughput (pairs/s)",
        "",
        f"Machine: {platform.processor() or platform.machine()}, {m['cpus']} CPUs, "
        f"jax {m['jax']}, torch {m['torch']} (default {m['torch_default_threads']} threads), "
        f"PJRT_NPROC={m['PJRT_NPROC']}, XLA_FLAGS={m['XLA_FLAGS']!r}. Load average (1 min) at "
        f"the end: {m['load_avg_1m_end']:.1f}. Ensemble of {K} MLPs 2x{HIDDEN}, obs {OBS}, act "
        f"{ACT}, {FLOP_PER_PAIR / 1e6:.2f} MFLOP/pair; {n_pairs} pairs ({a.demos} demos x {T} "
        f"steps; the per-demo loops score the first {a.per_demo}). {a.rounds} interleaved "
        "rounds; figures are median [min–max] over rounds, ratios are taken within a round.",
        f"Same weights: max |difference| of ℓ and ν, ours vs torch = "
        f"{res['max_abs_diff_vs_torch']:.2e}.",
        "",
        "| scorer | pairs/s | GFLOP/s (median) | note |",
        "|---|---:|---:|---|",
    ]
    lines += [f"| {n} | {_fmt(v)} | {v['median'] * gf:.1f} | {note} |" for n, v, note in rows]
    mg = res["matmul_gflops"]
    lines += [
        f"| plain fp32 matmul {a.matmul_n}³, JAX | | {_fmt(mg['jax_mm'], '{:.1f}')} | |",
        f"| plain fp32 matmul {a.matmul_n}³, torch | | {_fmt(mg['torch_mm'], '{:.1f}')} | |",
        "",
        f"One {T}-step episode per `score_demos` call: {_fmt(res['episode_ms'], '{:.1f}')} ms; "
        f"its FLOP time at the JAX matmul's speed: {_fmt(res['episode_flop_ms'], '{:.1f}')} ms.",
        "",
        "| target | measured: median [min–max] over rounds | target | verdict |",
        "|---|---:|---:|---|",
    ]
    bc = res["best_chunk"]
    rr = res["ratio_rounds"]
    checks = [
        ("one_pass", f"ours (chunk {bc}) / torch per-demo one-pass loop", "{:.2f}x", 1, False),
        ("batched", f"ours (chunk {bc}) / torch batched loop", "{:.2f}x", 1, False),
        ("matmul", f"ours (chunk {bc}) GFLOP/s / JAX matmul GFLOP/s", "{:.0f}%", 100, False),
        ("chunk1024", f"chunk 1024 / chunk {bc}", "{:.0f}%", 100, False),
        ("episode", f"one {T}-step episode / its FLOP time", "{:.2f}x", 1, True),
    ]
    for key, label, f, scale, below in checks:
        if key not in r:
            continue
        target = TARGETS[key]
        tgt = ("<= " if below else ">= ") + (
            f"{100 * target:.0f}%" if scale == 100 else f"{target:g}x"
        )
        verdict = _verdict(r[key], rr[key], target, below)
        lines.append(f"| {label} | {_fmt(r[key], f, scale)} | {tgt} | {verdict} |")
    lines += [
        f"| ours (chunk {bc}) / torch per-demo loop (the original code) | "
        f"{_fmt(r['per_demo'], '{:.2f}x')} | | |",
        "",
        "Reference thread settings (faster median): "
        + ", ".join(f"{k} {v}" for k, v in th.items())
        + ".",
        f"Command: `{' '.join([Path(sys.executable).name, *sys.argv])}`",
    ]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
