"""Evidence the phenomenon is there: do a conflicting operator's demos hurt naive BC?

For one task, collect ``--episodes`` successful demos of the base operator and of every
operator in ``--operators`` (C MuJoCo; collection seed 0 for every operator, so all start
from the same initial states), train an MLP ensemble on base-only and on base + each operator
(naive union) for ``--seeds`` training seeds, evaluate every checkpoint on the same
``--rollouts`` seeded initial states (C MuJoCo backend) and print a Markdown table of
success % mean (std) over seeds, best checkpoint per seed (as the paper's protocol selects).
Work files (demos, runs, rollouts) go under ``--work`` and are reused when present, so an
interrupted run resumes.

Example::

    python benchmarks/phenomenon.py --task square-nut \
        --operators same-style,conflict-flip --epochs 150 --hidden 256 --members 2 --seeds 3 \
        --out benchmarks/results/phenomenon-square-nut.md
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from elicit_jax.runtime import configure


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--task", default="square-nut")
    p.add_argument("--operators", default="same-style,mild,conflict-flip")
    p.add_argument("--base", default="base", help="the base operator")
    p.add_argument("--episodes", type=int, default=50, help="demos per operator")
    p.add_argument("--epochs", type=int, default=150)
    p.add_argument("--hidden", type=int, default=256, help="width of the 2 hidden layers")
    p.add_argument("--members", type=int, default=2, help="ensemble members")
    p.add_argument("--seeds", type=int, default=3, help="training seeds 0..N-1")
    p.add_argument("--rollouts", type=int, default=50)
    p.add_argument("--work", type=Path, default=Path("/tmp/elicit-phenomenon"))
    p.add_argument("--out", type=Path, default=None, help="also write the table here")
    return p.parse_args()


def main() -> None:
    args = parse_args()
    configure()
    from elicit_jax.data.demos import concat_demos, read_demos
    from elicit_jax.policy.config import TrainConfig
    from elicit_jax.policy.train import train_policy
    from elicit_jax.sim.collect import CollectConfig, collect
    from elicit_jax.sim.evaluate import EvalConfig, evaluate_policies

    t0 = time.time()
    ops = [o for o in args.operators.split(",") if o]
    demo_dir = args.work / args.task / f"demos-{args.episodes}"
    demo_dir.mkdir(parents=True, exist_ok=True)
    demos = {}
    for op in [args.base, *ops]:
        path = demo_dir / f"{op}.parquet"
        if not path.exists():
            collect(
                CollectConfig(task=args.task, operator=op, episodes=args.episodes, seed=0), path
            )
        demos[op] = read_demos(path)
    print(f"collected ({time.time() - t0:.0f} s)", flush=True)

    cfg = TrainConfig(
        hidden=(args.hidden, args.hidden),
        ensemble_size=args.members,
        epochs=args.epochs,
        checkpoint_every=max(args.epochs // 4, 1),
        seeds=tuple(range(args.seeds)),
        progress_every=max(args.epochs // 10, 1),
    )
    run_root = args.work / args.task / f"e{args.epochs}-h{args.hidden}-k{args.members}"
    run_root = run_root / f"s{args.seeds}-n{args.episodes}"
    runs = []
    for op in [args.base, *ops]:
        run = run_root / f"run-{op}"
        if not run.exists():
            data = demos[op] if op == args.base else concat_demos([demos[args.base], demos[op]])
            train_policy(data, cfg, run, quiet=True)
        label = f"{args.base}-only" if op == args.base else f"+{op}"
        runs.append(f"{label}={run}")
        print(f"trained {label} ({time.time() - t0:.0f} s)", flush=True)

    ecfg = EvalConfig(
        task=args.task, rollouts=args.rollouts, checkpoints=("all",), select="best",
        backend="mujoco",
    )  # fmt: skip
    _, summary = evaluate_policies(runs, ecfg, out=run_root / "rollouts.parquet")
    order = {r.split("=")[0]: i for i, r in enumerate(runs)}
    summary = summary.sort_values("policy", key=lambda s: s.map(order))
    lines = [
        f"## Naive BC on `{args.task}`: base-only vs base + each operator",
        "",
        f"MLP {args.hidden}x{args.hidden}, {args.members} members, {args.epochs} epochs, "
        f"checkpoints every {cfg.checkpoint_every}, best checkpoint per seed, "
        f"{args.seeds} training seeds, {args.episodes} demos per operator, "
        f"{args.rollouts} rollouts (C MuJoCo) on the same seeded initial states.",
        "",
        "| training data | success % mean (std) over seeds | mean length |",
        "|---|---|---|",
    ]
    for _, row in summary.iterrows():
        lines.append(
            f"| {row['policy']} | {row['success_mean']:.1f} ({row['success_std']:.1f}) "
            f"| {row['mean_length']:.0f} |"
        )
    lines += ["", f"Wall time: {time.time() - t0:.0f} s."]
    table = "\n".join(lines)
    print(table, flush=True)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(table + "\n")


if __name__ == "__main__":
    main()
