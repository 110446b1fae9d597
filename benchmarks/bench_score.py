"""Scoring throughput: our chunked, vmapped, jitted scorer vs the original code's PyTorch loop.

Paper sizes: an ensemble of 5 MLPs (2 hidden layers of 1024, LayerNorm, ReLU, tanh head),
23-D observations, 7-D actions, demonstrations of 90 steps. Three ways to score the same pairs
with the same weights (our Flax parameters copied into torch):

* ``ours``: :func:`elicit_jax.compat.score.score_demos` — fixed-size chunks, one compiled
  function (the compile is timed separately and excluded);
* ``torch per-demo``: the original code's approach (kanishkg/elicit ``src/util/util.py:
  get_compatibility`` calling ``src/models/ensemble.py: Ensemble.get_compatibility``), called
  once per 90-step demonstration (CPU, ``torch.no_grad``): one pass over the 5 members for the
  likelihood (member-average of clamped squared errors) and a second pass for the novelty
  (unbiased std across members), then M;
* ``torch per-demo, one pass``: a stronger reference than the original — the same per-demo
  calls, but both measures from a single member loop;
* ``torch batched``: the original two-pass loop on large batches (``--torch-batch`` pairs).

Ours is run with the same definitions (``likelihood="member-average"``, ``ddof=1``) so the
numbers can be compared pair by pair.

Also measured in the same run: a plain fp32 matmul (``--matmul-n``³) in JAX and in torch, as
the machine's attainable GFLOP/s (best single call of 5 per repeat, so the peak is not
underestimated on a shared machine). FLOPs per pair = 5 members × 2 × (23·1024 + 1024·1024 +
1024·7) ≈ 10.8 MFLOP (LayerNorm, activations and the score arithmetic are not counted).

Run: ``.venv/bin/python benchmarks/bench_score.py [--quick] [--out results/score.md]``
(needs the ``bench`` extra: ``pip install 'elicit-jax[bench]'``).
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import sys
import tempfile
import time
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
    p.add_argument("--repeats", type=int, default=5, help="timed repeats (best is reported)")
    p.add_argument("--quick", action="store_true", help="fewer demos and repeats")
    p.add_argument("--out", type=Path, default=None, help="write a Markdown report here")
    a = p.parse_args()
    if a.quick:
        a.demos, a.per_demo, a.repeats = 60, 15, 3
    return a


def _cfg(chunk: int):
    """Our scorer with the original code's definitions, at a chunk size."""
    from elicit_jax.compat.measures import ScoreConfig

    return ScoreConfig(likelihood="member-average", ddof=1, chunk_size=chunk)


def _best(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


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
    from elicit_jax.policy.base import init_policy, normalization_stats

    a = _args()
    torch.set_num_threads(os.cpu_count() or 1)
    rng = np.random.default_rng(0)
    eps = [
        {
            "obs": rng.normal(size=(T, OBS)).astype(np.float32),
            "action": rng.uniform(-1, 1, size=(T, ACT)).astype(np.float32),
        }
        for _ in range(a.demos)
    ]
    demos = from_episodes(eps, operators="op")
    mean, std = normalization_stats(demos.obs)
    policy = init_policy(
        jax.random.key(0),
        kind="mlp",
        obs_dim=OBS,
        action_dim=ACT,
        n_members=K,
        hidden=(HIDDEN, HIDDEN),
        dropout=0.5,
        obs_mean=mean,
        obs_std=std,
    )
    n_pairs = demos.n_steps
    rows: list[tuple[str, float, str]] = []

    # --- compile ours at each chunk size; copy the weights into torch ---
    n = a.matmul_n
    xa = jax.random.normal(jax.random.key(1), (n, n), jnp.float32)
    mm = jax.jit(lambda x: x @ x)
    mm(xa).block_until_ready()
    xt = torch.randn(n, n)
    torch.mm(xt, xt)
    chunks = [int(x) for x in a.chunks.split(",")]
    compile_s, ref = {}, None
    for c in chunks:
        t = time.perf_counter()
        ref = score_demos(policy, demos, _cfg(c))
        compile_s[c] = time.perf_counter() - t
    models = _torch_models(policy)
    tmean, tstd = torch.from_numpy(np.asarray(mean)), torch.from_numpy(np.asarray(std))
    obs_t, act_t = torch.from_numpy(demos.obs), torch.from_numpy(demos.action)
    ell_t, nu_t, _ = _torch_score(models, tmean, tstd, obs_t, act_t)
    err = max(
        float(np.abs(ell_t.numpy() - ref["likelihood"]).max()),
        float(np.abs(nu_t.numpy() - ref["novelty"]).max()),
    )

    def per_demo():
        for i in range(a.per_demo):
            s = slice(i * T, (i + 1) * T)
            _torch_score(models, tmean, tstd, obs_t[s], act_t[s])

    def per_demo_one_pass():
        for i in range(a.per_demo):
            s = slice(i * T, (i + 1) * T)
            _torch_score_one_pass(models, tmean, tstd, obs_t[s], act_t[s])

    def batched():
        b = a.torch_batch
        for s in range(0, n_pairs, b):
            _torch_score(models, tmean, tstd, obs_t[s : s + b], act_t[s : s + b])

    # --- timed: all contenders interleaved in each repeat (the machine is shared), best kept ---
    jobs = {f"ours{c}": (lambda c=c: score_demos(policy, demos, _cfg(c))) for c in chunks}
    tmp = Path(tempfile.mkdtemp(prefix="bench_score_"))
    write_demos(tmp / "demos.parquet", demos)

    def streamed():
        cfg = _cfg(stream_chunk)
        score_file(policy, tmp / "demos.parquet", tmp / "scores.parquet", cfg, progress=False)

    stream_chunk = ScoreConfig().chunk_size
    streamed()
    jobs |= {
        "streamed": streamed,
        "per_demo": per_demo,
        "per_demo_one_pass": per_demo_one_pass,
        "batched": batched,
        "jax_mm": lambda: mm(xa).block_until_ready(),
        "torch_mm": lambda: torch.mm(xt, xt),
    }
    best = {k: float("inf") for k in jobs}
    for _ in range(a.repeats):
        for k, fn in jobs.items():
            # matmul calls are short: time 5 back to back so its peak is not underestimated
            best[k] = min(best[k], _best(fn, 5 if k.endswith("_mm") else 1))
    ours = {c: (n_pairs / best[f"ours{c}"], compile_s[c]) for c in chunks}
    best_c = max(ours, key=lambda c: ours[c][0])
    ours_pps = ours[best_c][0]
    per_demo_pps = a.per_demo * T / best["per_demo"]
    one_pass_pps = a.per_demo * T / best["per_demo_one_pass"]
    batched_pps = n_pairs / best["batched"]
    jax_mm = 2 * n**3 / best["jax_mm"] / 1e9
    torch_mm = 2 * n**3 / best["torch_mm"] / 1e9

    def gf(pps: float) -> float:
        return pps * FLOP_PER_PAIR / 1e9

    for c, (pps, comp) in sorted(ours.items()):
        rows.append((f"ours, chunk {c}", pps, f"compile+first call {comp:.1f} s"))
    rows.append(
        (
            f"ours, streamed Parquet -> Parquet (score_file, chunk {stream_chunk})",
            n_pairs / best["streamed"],
            "includes reading, writing, episode summary",
        )
    )
    rows.append((f"torch per-demo loop ({T}-step demos)", per_demo_pps, "the original code"))
    rows.append((f"torch per-demo, one pass ({T}-step demos)", one_pass_pps, "stronger reference"))
    rows.append((f"torch batched loop ({a.torch_batch} pairs/call)", batched_pps, ""))
    lines = [
        "# Scoring throughput (pairs/s)",
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPU cores "
        f"(shared), jax {jax.__version__}, torch {torch.__version__} "
        f"({torch.get_num_threads()} threads). Ensemble of {K} MLPs 2x{HIDDEN}, obs {OBS}, "
        f"act {ACT}; {n_pairs} pairs ({a.demos} demos x {T} steps; the per-demo loop scores "
        f"the first {a.per_demo}). Best of {a.repeats} interleaved repeats. "
        f"{FLOP_PER_PAIR / 1e6:.2f} MFLOP/pair. XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}. "
        f"Load average at the end: {os.getloadavg()[0]:.1f} (other jobs share the cores).",
        f"Same weights: max |difference| of ℓ and ν, ours vs torch = {err:.2e}.",
        "",
        "| scorer | pairs/s | GFLOP/s | note |",
        "|---|---:|---:|---|",
    ]
    lines += [f"| {name} | {pps:,.0f} | {gf(pps):.1f} | {note} |" for name, pps, note in rows]
    lines += [
        f"| plain fp32 matmul {n}³, JAX | | {jax_mm:.1f} | |",
        f"| plain fp32 matmul {n}³, torch | | {torch_mm:.1f} | |",
        "",
        "| ratio | value | target |",
        "|---|---:|---:|",
        f"| ours (chunk {best_c}) / torch per-demo loop | {ours_pps / per_demo_pps:.1f}x | >= 5x |",
        f"| ours / torch per-demo, one pass | {ours_pps / one_pass_pps:.1f}x | |",
        f"| ours / torch batched loop | {ours_pps / batched_pps:.2f}x | >= 1x |",
        f"| ours GFLOP/s / JAX matmul GFLOP/s | {100 * gf(ours_pps) / jax_mm:.0f}% | >= 60% |",
        f"| ours GFLOP/s / best matmul GFLOP/s | "
        f"{100 * gf(ours_pps) / max(jax_mm, torch_mm):.0f}% | |",
        "",
        f"Command: `{' '.join([Path(sys.executable).name, *sys.argv])}`",
    ]
    shutil.rmtree(tmp, ignore_errors=True)
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(text)


if __name__ == "__main__":
    main()
