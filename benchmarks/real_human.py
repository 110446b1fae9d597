"""Real human demonstrations in robosuite's nut assembly, judged against a scripted base policy.

The only public human teleoperation of robosuite's nut assembly (Panda, OSC_POSE, 20 Hz) that
this project could reach is the sample demonstration robosuite 1.0.1 ships in its wheel on
PyPI (MIT licence): ``robosuite/models/assets/demonstrations/nut-assembly/panda/demo.hdf5``,
ONE human demonstration of ``NutAssembly`` recorded on 2020-09-04 with robosuite's
``collect_human_demonstrations`` (MuJoCo states and actions, no observations). The person
puts the round nut on its peg first, then the square nut on its peg. This script cuts it
into the two single-nut tasks robomimic and the paper use, at the step where robosuite's own
check first sees that nut on its peg:

- ``robosuite-round``: steps 0..(round nut on its peg), from the environment's start pose;
- ``robosuite-square``: the steps after that up to the square nut on its peg (the arm starts
  above the round peg, not at the start pose, and the round nut sits on its peg).

Each cut is replayed state by state in robosuite 1.5 (``NutAssemblySquare`` /
``NutAssemblyRound``, this project's backend) to read robomimic's low-dimensional
observations (``robot0_eef_pos``, ``robot0_eef_quat``, ``robot0_gripper_qpos``, ``object``),
and written as a robomimic file. Then the method's walk runs against scripted operators in
the same environment: collect ``base`` demos (training), held-out ``base`` and
``conflict-flip-pause`` demos (contrast sets), train the base policy, import the human cut,
score everything, fit thresholds on the contrast sets (trust verdict), map, filter, and --
with ``--rollouts`` -- evaluate base-only, naive (base + human) and filtered policies on the
same seeded initial states. Work files go under ``--work`` and are reused when present.

The source is never downloaded here. Get it with the ordinary client, then pass its path::

    pip download --no-deps robosuite==1.0.1 -d /tmp/rs101
    python benchmarks/real_human.py /tmp/rs101/robosuite-1.0.1-py3-none-any.whl \\
        --task robosuite-square --work /tmp/real-human \\
        --out benchmarks/results/real-human-robosuite-square.md

``SOURCE`` may also be the extracted ``demo.hdf5``; its SHA-256 is checked either way.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from real_human_source import (
    SOURCE_MEMBER,
    SOURCE_SHA256,
    SOURCE_URL,
    TASKS,
    WHEEL_SHA256,
    cut,
    load_demo,
    read_source,
    replay_check,
    write_robomimic,
)


def add_study_arguments(p: argparse.ArgumentParser) -> None:
    """The options both real-operator scripts take: the report, the scripted base and
    contrast sets, the base policy's training."""
    p.add_argument("--out", type=Path, help="results Markdown to write")
    p.add_argument("--episodes", type=int, default=40, help="scripted base demos for training")
    p.add_argument("--contrast", type=int, default=10, help="demos per contrast set")
    p.add_argument("--conflict", default="conflict-flip-pause", help="the conflicting style")
    p.add_argument("--profile", default="cpu", help="training profile of the base policy")
    p.add_argument("--epochs", type=int, default=0, help="override the profile's epochs (0: no)")


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("source", type=Path, help="robosuite-1.0.1 wheel or its nut-assembly demo.hdf5")
    p.add_argument("--task", choices=sorted(TASKS), default="robosuite-square")
    p.add_argument("--work", type=Path, default=Path("/tmp/elicit-real-human"))
    add_study_arguments(p)
    p.add_argument("--rollouts", type=int, default=0, help="evaluate base/naive/filtered (0: no)")
    p.add_argument("--threads", type=int, default=2, help="robosuite worker processes")
    return p.parse_args()


def cli(*args: str, log: Path) -> None:
    """Run one elicit-jax command (niced), its output in ``log``; stop on failure."""
    cmd = ["nice", "-n", "10", sys.executable, "-c", "from elicit_jax.cli import main; main()"]
    t0 = time.perf_counter()
    with log.open("w") as fh:
        rc = subprocess.run([*cmd, *args], stdout=fh, stderr=subprocess.STDOUT).returncode
    print(f"  elicit-jax {' '.join(args)}  [{time.perf_counter() - t0:.0f} s]", flush=True)
    if rc:
        sys.exit(f"error: elicit-jax {args[0]} failed, see {log}")


def prepare(args: argparse.Namespace, work: Path) -> dict[str, Any]:
    """The human segment as a robomimic file under ``work`` (rebuilt from the source)."""
    data = read_source(args.source)
    demo = load_demo(data)
    span = cut(args.task, demo["states"])
    human = work / f"human-{args.task}.hdf5"
    if not human.exists():
        write_robomimic(human, args.task, demo, span)
    return {"demo": demo, "span": span, "file": human}


def run_walk(args: argparse.Namespace, work: Path, human: Path) -> None:
    """Collect, train, import, score, fit, map and filter (outputs reused when present)."""
    t, n, c = args.task, str(args.episodes), str(args.contrast)
    th = ["--threads", str(args.threads)]
    steps: list[tuple[str, list[str]]] = [
        ("base.parquet", ["collect", "--task", t, "--operator", "base", "--episodes", n,
                          "--seed", "0", *th]),
        ("heldout.parquet", ["collect", "--task", t, "--operator", "base", "--episodes", c,
                             "--seed", "1", *th]),
        ("conflict.parquet", ["collect", "--task", t, "--operator", args.conflict,
                              "--episodes", c, "--seed", "2", *th]),
        ("human.parquet", ["import", str(human), "--format", "robomimic", "--task", t,
                           "--operator", "human"]),
        ("contrast.parquet", ["demos", "concat", str(work / "heldout.parquet"),
                              str(work / "conflict.parquet"), str(work / "human.parquet")]),
    ]  # fmt: skip
    train = ["train", "--demos", str(work / "base.parquet"), "--profile", args.profile, "-q"]
    if args.epochs:
        train += ["--epochs", str(args.epochs)]
    steps.append(("base_run", [*train, "--out"]))
    steps += [
        ("scores.parquet", ["score", "--policy", str(work / "base_run"), "--demos",
                            str(work / "contrast.parquet")]),
        ("thresholds.json", ["fit-thresholds", "--scores", str(work / "scores.parquet"),
                             "--compatible", "operator:base", "--incompatible",
                             f"operator:{args.conflict}", "--base", str(work / "base.parquet")]),
        ("scores_fitted.parquet", ["score", "--policy", str(work / "base_run"), "--demos",
                                   str(work / "contrast.parquet"), "--thresholds",
                                   str(work / "thresholds.json")]),
        ("map.html", ["map", "--scores", str(work / "scores_fitted.parquet"), "--thresholds",
                      str(work / "thresholds.json")]),
        ("human_scores.parquet", ["score", "--policy", str(work / "base_run"), "--demos",
                                  str(work / "human.parquet"), "--thresholds",
                                  str(work / "thresholds.json")]),
        ("filtered.parquet", ["filter", "--scores", str(work / "human_scores.parquet"),
                              "--demos", str(work / "human.parquet"), "--base",
                              str(work / "base.parquet"), "--thresholds",
                              str(work / "thresholds.json"), "--level", "pair"]),
    ]  # fmt: skip
    for out, cmd in steps:
        target = work / out
        if target.exists():
            print(f"  reuse {target}")
            continue
        flag = [] if cmd[-1] == "--out" else ["-o"]
        cli(*cmd, *flag, str(target), log=work / f"{out.split('.')[0]}.log")


def run_rollouts(args: argparse.Namespace, work: Path) -> None:
    """Train naive (base + human) and filtered policies; evaluate all three, same states."""
    if not (work / "naive.parquet").exists():
        cli("demos", "concat", str(work / "base.parquet"), str(work / "human.parquet"),
            "-o", str(work / "naive.parquet"), log=work / "naive.log")  # fmt: skip
    for name in ("naive", "filtered"):
        run = work / f"{name}_run"
        if not run.exists():
            cmd = ["train", "--demos", str(work / f"{name}.parquet"), "--profile", args.profile]
            cmd += ["--epochs", str(args.epochs)] if args.epochs else []
            cli(*cmd, "-q", "--out", str(run), log=work / f"{name}_train.log")
    evals = work / "evals.parquet"
    if not evals.exists():
        runs = {"base-only": "base_run", "naive": "naive_run", "filtered": "filtered_run"}
        pols = [x for k, v in runs.items() for x in ("--policy", f"{k}={work / v}")]
        cli("evaluate", *pols, "--task", args.task,
            "--rollouts", str(args.rollouts), "--workers", str(args.threads), "-o", str(evals),
            log=work / "evaluate.log")  # fmt: skip


PAPER_THRESHOLDS = {"robosuite-square": (0.4, 0.05), "robosuite-round": (0.35, 0.05)}
"""The paper's hand-set (λ, η) of Square Nut and Round Nut, for reference."""


def per_operator(path: Path, lam: float, eta: float) -> dict[str, dict[str, float]]:
    """Per operator: episodes, rejected (5% rule), mean ℓ, ν and fraction incompatible."""
    from elicit_jax.compat.score_file import read_scores

    _, s = read_scores(path, ["episode", "operator", "likelihood", "novelty"])
    inc = (s["likelihood"] > lam) & (s["novelty"] < eta)
    out: dict[str, dict[str, float]] = {}
    for op in dict.fromkeys(map(str, s["operator"])):
        sel = s["operator"].astype(str) == op
        eps = np.unique(s["episode"][sel])
        fr = np.array([inc[sel & (s["episode"] == e)].mean() for e in eps])
        out[op] = {
            "episodes": len(eps),
            "rejected": int((fr > 0.05).sum()),
            "pairs": int(sel.sum()),
            "ell": float(s["likelihood"][sel].mean()),
            "nu": float(s["novelty"][sel].mean()),
            "frac_inc": float(inc[sel].mean()),
            "frac_inc_min": float(fr.min()),
            "frac_inc_max": float(fr.max()),
        }
    return out


def human_profile(path: Path, lam: float, eta: float, bins: int = 5) -> tuple[list[float], float]:
    """The human demo's fraction of incompatible pairs in ``bins`` equal stretches of time,
    and its fraction of pairs in unfamiliar states (ν ≥ η: never flagged, whatever ℓ)."""
    from elicit_jax.compat.score_file import read_scores

    _, s = read_scores(path, ["operator", "likelihood", "novelty"])
    sel = s["operator"].astype(str) == "human"
    inc = (s["likelihood"][sel] > lam) & (s["novelty"][sel] < eta)
    novel = float((s["novelty"][sel] >= eta).mean())
    return [float(part.mean()) for part in np.array_split(inc, bins)], novel


def success_rates(path: Path) -> dict[str, np.ndarray]:
    """Per policy label of an evaluation file: success of each rollout, in rollout order
    (rollout i starts from the same seeded initial state for every policy)."""
    import pandas as pd

    df = pd.read_parquet(path, columns=["policy", "rollout", "success"])
    return {
        str(k): g.sort_values("rollout")["success"].to_numpy(dtype=float)
        for k, g in df.groupby("policy", sort=False)
    }


def fmt_ops(ops: dict[str, dict[str, float]]) -> list[str]:
    rows = ["| operator | demos | pairs | mean ℓ | mean ν | incompatible pairs | rejected demos |",
            "|---|---|---|---|---|---|---|"]  # fmt: skip
    for op, r in ops.items():
        rng = (f" ({100 * r['frac_inc_min']:.1f}–{100 * r['frac_inc_max']:.1f}% per demo)"
               if r["episodes"] > 1 else "")  # fmt: skip
        rows.append(
            f"| {op} | {r['episodes']} | {r['pairs']} | {r['ell']:.3f} | {r['nu']:.4f} | "
            f"{100 * r['frac_inc']:.1f}%{rng} | {r['rejected']} of {r['episodes']} |"
        )
    return rows


def source_lines(prep: dict[str, Any]) -> list[str]:
    """The Markdown "Source" section: the public demonstration, its segment, the replay."""
    rp = prep["replay"]
    s, e = prep["span"]
    return [
        "## Source",
        "",
        f"- robosuite 1.0.1 wheel on PyPI ({SOURCE_URL}), MIT licence; wheel SHA-256 "
        f"`{WHEEL_SHA256}`.",
        f"- member `{SOURCE_MEMBER}` (SHA-256 `{SOURCE_SHA256}`): one human teleoperated "
        f"demonstration of robosuite `NutAssembly` (Panda, OSC_POSE, 20 Hz), recorded "
        f"{prep['demo']['date']} with robosuite {prep['demo']['repository_version']}; "
        f"{len(prep['demo']['states'])} steps, round nut placed first, then the square nut.",
        f"- this task's segment: steps {s}..{e - 1} ({e - s} steps), ending at the first step "
        "robosuite's check sees the nut on its peg; observations read by replaying the recorded "
        "MuJoCo states in robosuite 1.5.1. The data is not committed: the script rebuilds it.",
        f"- fidelity: the recorded actions replayed open loop in robosuite 1.5.1 from the "
        f"segment's first state drift {100 * rp['err_50']:.1f} cm from the recorded hand "
        f"within 50 steps ({100 * rp['err_max']:.1f} cm at most) and "
        f"{'do' if rp['success'] else 'do not'} place the nut (robosuite 1.0 → 1.5 dynamics "
        "and controller differ; the observations above come from the recorded states, not "
        "from this replay).",
    ]  # fmt: skip


def rollout_lines(args: argparse.Namespace, evals: Path) -> list[str]:
    """The Markdown "Rollouts" section: success per policy and their paired differences."""
    lines = ["", "## Rollouts (same seeded initial states)", "",
             "| policy | trained on | success |", "|---|---|---|"]  # fmt: skip
    what = {"base-only": f"{args.episodes} base demos", "naive": "base + the human demo",
            "filtered": "base + the human demo's compatible pairs (M-filtered)"}  # fmt: skip
    from elicit_jax.stats import format_diff, paired_t_interval

    rates = success_rates(evals)
    for k, v in rates.items():
        lines.append(f"| {k} | {what.get(k, k)} | {int(v.sum())}/{len(v)} "
                     f"({100 * v.mean():.0f}%) |")  # fmt: skip
    pairs = [("naive", "base-only"), ("filtered", "base-only"), ("filtered", "naive")]
    lines += ["", "Paired differences over the rollouts' shared initial states, points "
              "[95% interval; * excludes 0]: "
              + "; ".join(f"{a} − {b} {format_diff(paired_t_interval(rates[a], rates[b]))}"
                          for a, b in pairs if a in rates and b in rates) + ".",
              "", "One training seed per policy and one demonstration: the intervals "
              "cover the initial states, not training seeds, so a difference here is not "
              "evidence of an effect of filtering."]  # fmt: skip
    return lines


def report(args: argparse.Namespace, work: Path, prep: dict[str, Any], cmd: str) -> str:
    """The results Markdown."""
    thr = json.loads((work / "thresholds.json").read_text())
    lam, eta, rep = thr["lambda"], thr["eta"], thr["report"]
    trust = rep["trust"]
    fitted = per_operator(work / "scores_fitted.parquet", lam, eta)
    plam, peta = PAPER_THRESHOLDS[args.task]
    paper = per_operator(work / "scores_fitted.parquet", plam, peta)
    prof, novel = human_profile(work / "human_scores.parquet", lam, eta)
    h = fitted["human"]
    verdict = "rejected" if h["rejected"] else "accepted"
    loo = "n/a" if rep.get("loo_accuracy") is None else f"{rep['loo_accuracy']:.2f}"
    lines = [
        f"# Real human demonstration on `{args.task}` ({TASKS[args.task][0]})",
        "",
        f"Command: `{cmd}`",
        "",
        *source_lines(prep),
        "",
        "## Against a scripted base policy",
        "",
        f"Base policy: `{args.profile}` profile"
        f"{f', {args.epochs} epochs' if args.epochs else ''}, trained on {args.episodes} "
        f"scripted `base` demos (collection seed 0). Contrast sets: {args.contrast} held-out "
        f"`base` demos (seed 1) as compatible, {args.contrast} `{args.conflict}` demos (seed 2) "
        "as incompatible. Scores in raw action units (the paper's definition).",
        "",
        f"**Fitted thresholds**: λ = {lam:.4g}, η = {eta:.4g}; balanced accuracy "
        f"{rep['balanced_accuracy']:.2f}, leave-one-out accuracy "
        f"{loo}"
        f", margin {rep.get('margin_steps')} grid steps. **Trust verdict: "
        f"{'trustworthy' if trust['trustworthy'] else 'NOT trustworthy'}**"
        + (f" ({'; '.join(trust['problems'] + trust['severe'])})" if not trust["trustworthy"]
           else "") + ".",
        "",
        f"**The human demonstration is {verdict}**: {100 * h['frac_inc']:.1f}% of its "
        f"{h['pairs']} pairs are incompatible (the 5% rule rejects above 5%). Fraction "
        "incompatible over five equal stretches of the demonstration: "
        + ", ".join(f"{100 * p:.0f}%" for p in prof) + f". {100 * novel:.0f}% of its pairs "
        "lie in states the base policy finds unfamiliar (ν ≥ η): the method never flags "
        "those, whatever the action.",
        "",
        "Under the fitted thresholds:",
        "",
        *fmt_ops(fitted),
        "",
        f"Under the paper's hand-set thresholds for this task (λ = {plam}, η = {peta}):",
        "",
        *fmt_ops(paper),
        "",
        "Map (ℓ vs ν per operator, threshold box): `map.html` in the work directory.",
    ]  # fmt: skip
    evals = work / "evals.parquet"
    if evals.exists():
        lines += rollout_lines(args, evals)
    return "\n".join(lines) + "\n"


def emit_report(text: str, out: Path | None) -> None:
    """Print the Markdown report and write it to ``out`` when given."""
    print(text)
    if out:
        out.write_text(text)
        print(f"wrote {out}")


def main() -> None:
    args = parse_args()
    work = args.work
    work.mkdir(parents=True, exist_ok=True)
    from elicit_jax.runtime import configure

    configure()
    print(f"[1/3] rebuilding the human segment of {args.task} from {args.source}")
    prep = prepare(args, work)
    prep["replay"] = replay_check(args.task, prep["file"])
    print("[2/3] the method's walk (collect, train, import, score, fit, map, filter)")
    run_walk(args, work, prep["file"])
    if args.rollouts:
        print(f"[3/3] naive vs filtered: train, evaluate {args.rollouts} rollouts each")
        run_rollouts(args, work)
    cmd = "python benchmarks/real_human.py " + " ".join(sys.argv[1:])
    emit_report(report(args, work, prep, cmd), args.out)


if __name__ == "__main__":
    main()
