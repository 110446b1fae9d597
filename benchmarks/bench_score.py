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
import shutil
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from bench_score_report import ACT, FLOP_PER_PAIR, HIDDEN, OBS, K, T, to_markdown


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

    return ScoreConfig.from_preset(
        "square-nut", likelihood="member-average", ddof=1, chunk_size=chunk
    )


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


def paper_policy():
    """The paper's policy (5 MLPs of 1024-1024) without dropout, as the rollout benchmarks
    act with it."""
    return bench_policy(HIDDEN, dropout=0.0)


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


def torch_models(policy):
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


def _data(a: argparse.Namespace):
    """``a.demos`` random demos (seed 0) at the paper's sizes, the first of them alone, and the
    benchmarked policy normalized on them, with its normalization statistics."""
    import numpy as np

    from elicit_jax.data.demos import from_episodes
    from elicit_jax.policy.base import normalization_stats

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
    return demos, episode, bench_policy(HIDDEN, mean, std), mean, std


def _matmuls(n: int):
    """The reference matmul: a compiled JAX ``x @ x`` on an ``n`` x ``n`` input, torch's input."""
    import jax
    import jax.numpy as jnp
    import torch

    xa = jax.random.normal(jax.random.key(1), (n, n), jnp.float32)
    mm = jax.jit(lambda x: x @ x)
    mm(xa).block_until_ready()
    return mm, xa, torch.randn(n, n)


def _compile(policy, demos, episode, chunks: list[int]):
    """Compile ours at each chunk size (seconds of compile + first call, and the last scores),
    and on one episode at the streaming chunk size (returned)."""
    from elicit_jax.compat.measures import ScoreConfig
    from elicit_jax.compat.score import score_demos

    compile_s, ref = {}, None
    for c in chunks:
        t = time.perf_counter()
        ref = score_demos(policy, demos, _cfg(c))
        compile_s[c] = time.perf_counter() - t
    stream_chunk = ScoreConfig.from_preset("square-nut").chunk_size
    score_demos(policy, episode, _cfg(stream_chunk))
    return compile_s, ref, stream_chunk


def _torch_reference(policy, mean, std, demos, ref):
    """The policy's weights in torch with the demos as tensors ``(models, mean, std, obs, act)``,
    and the max |difference| of ℓ and ν between the original code's scoring and ``ref``."""
    import numpy as np
    import torch

    models = torch_models(policy)
    tmean, tstd = torch.from_numpy(np.asarray(mean)), torch.from_numpy(np.asarray(std))
    obs_t, act_t = torch.from_numpy(demos.obs), torch.from_numpy(demos.action)
    ell_t, nu_t, _ = _torch_score(models, tmean, tstd, obs_t, act_t)
    err = max(
        float(np.abs(ell_t.numpy() - ref["likelihood"]).max()),
        float(np.abs(nu_t.numpy() - ref["novelty"]).max()),
    )
    return (models, tmean, tstd, obs_t, act_t), err


def _torch_loop(fn, tin, size: int, n_rows: int, threads: int) -> Callable[[], None]:
    """A job scoring the first ``n_rows`` pairs of ``tin`` with ``fn``, ``size`` pairs a call."""
    import torch

    models, tmean, tstd, obs_t, act_t = tin

    def run() -> None:
        torch.set_num_threads(threads)
        for s in range(0, n_rows, size):
            fn(models, tmean, tstd, obs_t[s : s + size], act_t[s : s + size])

    return run


def _torch_jobs(tin, refs: dict, settings: list[int], default_threads: int) -> dict:
    """Every torch loop at every thread setting, each warmed up once; threads reset after."""
    import torch

    jobs: dict[str, tuple[Callable[[], object], int]] = {}
    for name, (fn, size, rows) in refs.items():
        for th in settings:
            jobs[f"{name}_{th}t"] = (_torch_loop(fn, tin, size, rows, th), 1)
            jobs[f"{name}_{th}t"][0]()  # warm up
    torch.set_num_threads(default_threads)
    return jobs


def _figures(secs: dict, chunks: list[int], refs: dict, settings: list[int], n_pairs: int, n: int):
    """Pairs/s, GFLOP/s and the targets' ratios per round from the rounds' seconds."""
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
    return {
        "pairs_per_s": {k: spread(v) for k, v in pps.items()},
        "matmul_gflops": {k: spread(v) for k, v in gflops.items()},
        "episode_ms": spread([1e3 * t for t in secs["episode"]]),
        "episode_flop_ms": spread([1e3 * f for f in flop_s]),
        "ratios": {k: spread(v) for k, v in per_round.items()},
        "ratio_rounds": per_round,
        "reference_threads": ref_setting,
        "best_chunk": best_c,
    }


def main() -> None:
    from elicit_jax.runtime import configure

    configure()
    import jax
    import torch

    from elicit_jax.compat.score import score_demos
    from elicit_jax.compat.score_file import score_file
    from elicit_jax.data.demos import write_demos

    a = _args()
    demos, episode, policy, mean, std = _data(a)
    n_pairs = demos.n_steps
    mm, xa, xt = _matmuls(a.matmul_n)
    chunks = [int(x) for x in a.chunks.split(",")]
    compile_s, ref, stream_chunk = _compile(policy, demos, episode, chunks)
    tin, err = _torch_reference(policy, mean, std, demos, ref)
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
    jobs.update(_torch_jobs(tin, refs, settings, default_threads))
    jobs["jax_mm"] = (lambda: mm(xa).block_until_ready(), 5)
    jobs["torch_mm"] = (lambda: torch.mm(xt, xt), 5)
    jobs["torch_mm"][0]()
    secs = interleaved(jobs, a.rounds)
    shutil.rmtree(tmp, ignore_errors=True)
    result = {
        **_figures(secs, chunks, refs, settings, n_pairs, a.matmul_n),
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


if __name__ == "__main__":
    main()
