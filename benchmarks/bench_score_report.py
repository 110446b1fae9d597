"""The Markdown report of ``benchmarks/bench_score.py``, with the sizes and targets it reports.

The benchmarked sizes are the paper's: an ensemble of ``K`` MLPs of two ``HIDDEN``-unit layers,
``OBS``-D observations, ``ACT``-D actions, demonstrations of ``T`` steps. ``TARGETS`` are
issue #16's throughput targets; :func:`to_markdown` gives every measured ratio its verdict.
"""

from __future__ import annotations

import argparse
import platform
import sys
from pathlib import Path

OBS, ACT, K, HIDDEN, T = 23, 7, 5, 1024, 90
FLOP_PER_PAIR = K * 2 * (OBS * HIDDEN + HIDDEN * HIDDEN + HIDDEN * ACT)

TARGETS = {
    "one_pass": 1.2,  # best chunk / torch per-demo one-pass loop
    "batched": 1.5,  # best chunk / torch batched loop
    "matmul": 0.70,  # best chunk GFLOP/s / JAX matmul GFLOP/s
    "chunk1024": 0.80,  # chunk 1024 / best chunk
    "episode": 2.0,  # one 90-step episode's time / its FLOP time at the matmul's speed
}


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
