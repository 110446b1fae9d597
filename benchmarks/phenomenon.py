"""Is the phenomenon there? Do a new operator's demos lower naive BC below base-only?

For one task and each collection seed: collect ``--episodes`` successful demos of the base
operator and of every operator in ``--operators`` (C MuJoCo, or robosuite worker processes for
the ``robosuite-*`` tasks; within a collection seed every operator starts from the same initial
states), train an MLP ensemble on base-only and on base + each operator (naive union) for the
training seeds ``0..--seeds-1`` (vmapped in one call), evaluate every checkpoint on the same
``--rollouts`` seeded initial states of evaluation seed ``--eval-seed`` (same simulator) and
keep the best checkpoint per training seed (the paper's protocol; ``--checkpoints final``: the
final checkpoint only). The report gives, per collection seed, success % mean (std) over training
seeds and the paired difference (naive − base-only); over all collection seeds, the mean
difference with a 95% Student t interval over the collection seeds' differences of means
(the collection seed is the unit of replication), and each operator's collection success rate
(proficiency). Work files (demos, runs, rollouts) go under ``--work`` and are reused when
present, so an interrupted run resumes.

Example::

    python benchmarks/phenomenon.py --task square-nut --operators same-style,conflict-flip \\
        --collect-seeds 1-5 --seeds 3 --epochs 150 --hidden 256 --members 2 \\
        --out benchmarks/results/phenomenon-square-nut.md
    python benchmarks/phenomenon.py --task robosuite-square --operators same-style,mild,\
conflict-flip-pause --collect-seeds 1-5 --seeds 3 --epochs 100 --checkpoint-every 50 \
        --hidden 256 --members 5 --checkpoints final --workers 2 \
        --out benchmarks/results/phenomenon-robosuite-square.md

On robosuite, ``--workers`` is the number of environment processes of collection and
evaluation (0: one per CPU) and ``--checkpoints final`` evaluates only the last checkpoint
(robosuite's rollouts are what a run spends its time on: docs/robosuite.md).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.runtime import configure


def seed_list(text: str) -> list[int]:
    """``"1-3,7"`` -> ``[1, 2, 3, 7]``."""
    out: list[int] = []
    for part in filter(None, text.split(",")):
        lo, _, hi = part.partition("-")
        out += list(range(int(lo), int(hi or lo) + 1))
    return out


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--task", default="square-nut")
    p.add_argument("--operators", default="same-style,conflict-flip")
    p.add_argument("--base", default="base", help="the base operator")
    p.add_argument("--episodes", type=int, default=50, help="demos per operator")
    p.add_argument("--collect-seeds", type=seed_list, default=seed_list("1-5"))
    p.add_argument("--epochs", type=int, default=150)
    p.add_argument("--checkpoint-every", type=int, default=25)
    p.add_argument("--hidden", type=int, default=256, help="width of the 2 hidden layers")
    p.add_argument("--members", type=int, default=2, help="ensemble members")
    p.add_argument("--batch-size", type=int, default=512)
    p.add_argument("--seeds", type=int, default=3, help="training seeds 0..N-1")
    p.add_argument("--rollouts", type=int, default=50)
    p.add_argument("--eval-seed", type=int, default=0, help="picks the evaluation states")
    p.add_argument(
        "--checkpoints",
        default="all",
        choices=["all", "final"],
        help="evaluate every saved checkpoint (best per seed) or the final one",
    )
    p.add_argument("--horizon", type=int, default=0, help="rollout steps (0: the task's)")
    p.add_argument(
        "--workers", type=int, default=0, help="robosuite: environment processes (0: one per CPU)"
    )
    p.add_argument("--work", type=Path, default=Path("/tmp/elicit-phenomenon"))
    p.add_argument("--out", type=Path, default=None, help="also write the report here")
    return p.parse_args()


def best_per_seed(rollouts: Any) -> np.ndarray:
    """(training seeds,) success % of each seed's best checkpoint, in seed order."""
    per = rollouts.groupby(["seed", "checkpoint"])["success"].mean().mul(100.0)
    return per.groupby(level="seed").max().sort_index().to_numpy()


def mean_std(x: np.ndarray) -> str:
    return f"{np.mean(x):.1f} ({np.std(x):.1f})"


class Study:
    """Collect, train and evaluate one (collection seed, condition) cell at a time, reusing
    whatever ``--work`` already holds."""

    def __init__(self, args: argparse.Namespace) -> None:
        from elicit_jax.policy.config import TrainConfig
        from elicit_jax.sim.evaluate import EvalConfig, is_robosuite_task

        self.args = args
        self.t0 = time.time()
        self.train_cfg = TrainConfig(
            hidden=(args.hidden, args.hidden),
            ensemble_size=args.members,
            batch_size=args.batch_size,
            epochs=args.epochs,
            checkpoint_every=args.checkpoint_every,
            seeds=tuple(range(args.seeds)),
            progress_every=max(args.epochs // 10, 1),
        )
        self.eval_cfg = EvalConfig(
            task=args.task, rollouts=args.rollouts, seed=args.eval_seed,
            checkpoints=(args.checkpoints,), select="best", workers=args.workers,
            horizon=args.horizon,
            backend="robosuite" if is_robosuite_task(args.task) else "mujoco",
        )  # fmt: skip
        self.root = args.work / args.task
        self.run_tag = (
            f"e{args.epochs}-c{args.checkpoint_every}-h{args.hidden}-k{args.members}"
            f"{'' if args.batch_size == 512 else f'-b{args.batch_size}'}"
            f"-s{args.seeds}-n{args.episodes}"
        )
        self.backend = self.eval_cfg.backend
        self.proficiency: dict[tuple[int, str], float] = {}

    def log(self, msg: str) -> None:
        print(f"[{time.time() - self.t0:6.0f} s] {msg}", flush=True)

    def demos(self, cseed: int, op: str) -> Any:
        from elicit_jax.artifact import read_header
        from elicit_jax.data.demos import read_demos
        from elicit_jax.sim.collect import CollectConfig, collect

        path = self.root / f"c{cseed}" / f"demos-{self.args.episodes}" / f"{op}.parquet"
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            cfg = CollectConfig(
                task=self.args.task,
                operator=op,
                episodes=self.args.episodes,
                seed=cseed,
                threads=self.args.workers,
            )
            collect(cfg, path)
            self.log(f"collected c{cseed} {op}")
        prov = read_header(path)["provenance"]
        self.proficiency[(cseed, op)] = float(prov["attempt_success_rate"])
        return read_demos(path)

    def success(self, cseed: int, op: str) -> np.ndarray:
        """Best-checkpoint success % per training seed of base-only (``op`` = base) or of
        base + ``op``."""
        import pandas as pd

        from elicit_jax.data.demos import concat_demos
        from elicit_jax.policy.train import train_policy
        from elicit_jax.sim.evaluate import evaluate_policies

        a = self.args
        run = self.root / f"c{cseed}" / self.run_tag / f"run-{op}"
        tag = ("" if a.checkpoints == "all" else f"-{a.checkpoints}") + (
            f"-h{a.horizon}" if a.horizon else ""
        )
        rollouts = run.with_name(f"rollouts-{op}-eval{a.eval_seed}-r{a.rollouts}{tag}.parquet")
        if not rollouts.exists():
            if not run.exists():
                base = self.demos(cseed, a.base)
                data = base if op == a.base else concat_demos([base, self.demos(cseed, op)])
                train_policy(data, self.train_cfg, run, quiet=True)
                self.log(f"trained c{cseed} {op}")
            evaluate_policies([f"{op}={run}"], self.eval_cfg, out=rollouts)
            self.log(f"evaluated c{cseed} {op}")
        self.demos(cseed, op)
        return best_per_seed(pd.read_parquet(rollouts))


def report(args: argparse.Namespace, study: Study, results: dict, wall: float) -> str:
    from elicit_jax.artifact import provenance, provenance_line
    from elicit_jax.stats import format_diff, paired_t_interval

    ops, cseeds = args.operators, args.collect_seeds
    cfg = study.train_cfg
    lines = [
        f"## Naive BC on `{args.task}`: base-only vs base + each operator",
        "",
        provenance_line(provenance()) + " (cells reused from earlier runs may be older.)",
        "",
        f"MLP {args.hidden}x{args.hidden}, {args.members} members, {args.epochs} epochs "
        f"(batch {args.batch_size}), "
        f"checkpoints every {cfg.checkpoint_every}, "
        f"{'best' if args.checkpoints == 'all' else 'final'} checkpoint per training seed, "
        f"training seeds {', '.join(map(str, cfg.seeds))}; {args.episodes} demos per operator; "
        f"collection seeds {', '.join(map(str, cseeds))}; {args.rollouts} rollouts "
        f"({'robosuite' if study.backend == 'robosuite' else 'C MuJoCo'}) "
        f"from evaluation seed {args.eval_seed}, the same initial states for every policy.",
        "",
        "### Per collection seed: success % mean (std) over training seeds; paired difference",
        "",
        "| collection seed | base-only | " + " | ".join(f"+{op} (naive)" for op in ops) + " |",
        "|---|---|" + "---|" * len(ops),
    ]
    for c in cseeds:
        base = results[(c, args.base)]
        cells = [
            f"{mean_std(results[(c, op)])}, {np.mean(results[(c, op)]) - np.mean(base):+.1f}"
            for op in ops
        ]
        lines.append(f"| {c} | {mean_std(base)} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "### Over collection seeds: difference naive − base-only, 95% t interval",
        "",
        "Student's t over the per-collection-seed differences of means (the collection seed is "
        "the unit of replication; the pipeline reports' interval). `*` marks an interval that "
        "excludes 0 for one operator alone; with several operators, read it with their number "
        "in mind (the pipeline reports adjust by Holm).",
        "",
        "| operator | base-only mean | naive mean | collection seeds below base "
        "| difference [95% t interval over collection seeds] |",
        "|---|---|---|---|---|",
    ]
    ref = {c: results[(c, args.base)] for c in cseeds}
    for op in ops:
        per_key = np.array([np.mean(results[(c, op)]) - np.mean(ref[c]) for c in cseeds])
        t = paired_t_interval(
            [np.mean(results[(c, op)]) for c in cseeds], [np.mean(ref[c]) for c in cseeds]
        )
        lines.append(
            f"| {op} | {np.mean([np.mean(v) for v in ref.values()]):.1f} "
            f"| {np.mean([np.mean(results[(c, op)]) for c in cseeds]):.1f} "
            f"| {int(np.sum(per_key < 0))} of {len(cseeds)} | {format_diff(t, scale=1.0)} |"
        )
    lines += [
        "",
        "### Proficiency: collection success rate of each operator (attempts that succeeded)",
        "",
        "| operator | " + " | ".join(f"c{c}" for c in cseeds) + " |",
        "|---|" + "---|" * len(cseeds),
    ]
    for op in [args.base, *ops]:
        rates = [f"{100 * study.proficiency[(c, op)]:.0f}%" for c in cseeds]
        lines.append(f"| {op} | " + " | ".join(rates) + " |")
    lines += [
        "",
        f"Wall time: {wall:.0f} s (work reused from earlier runs is not counted).",
        "",
        "Command:",
        "",
        "    " + command_line(args),
    ]
    return "\n".join(lines)


def command_line(args: argparse.Namespace) -> str:
    seeds = ",".join(map(str, args.collect_seeds))
    return (
        f"python benchmarks/phenomenon.py --task {args.task} --operators "
        f"{','.join(args.operators)} --collect-seeds {seeds} --seeds {args.seeds} "
        f"--epochs {args.epochs} --checkpoint-every {args.checkpoint_every} --hidden "
        f"{args.hidden} --members {args.members} --batch-size {args.batch_size} --episodes "
        f"{args.episodes} --rollouts "
        f"{args.rollouts} --eval-seed {args.eval_seed}"
        + ("" if args.checkpoints == "all" else f" --checkpoints {args.checkpoints}")
        + (f" --horizon {args.horizon}" if args.horizon else "")
    )


def main() -> None:
    args = parse_args()
    args.operators = [o for o in args.operators.split(",") if o]
    configure()
    study = Study(args)
    study.log(f"{args.task}: {dataclasses.asdict(study.train_cfg)}")
    results = {}
    for c in args.collect_seeds:
        for op in [args.base, *args.operators]:
            results[(c, op)] = study.success(c, op)
            study.log(f"c{c} {op}: {mean_std(results[(c, op)])}")
    text = report(args, study, results, time.time() - study.t0)
    print(text, flush=True)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
