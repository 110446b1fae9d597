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
import hashlib
import io
import json
import subprocess
import sys
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

SOURCE_URL = "https://pypi.org/project/robosuite/1.0.1/"
SOURCE_MEMBER = "robosuite/models/assets/demonstrations/nut-assembly/panda/demo.hdf5"
SOURCE_SHA256 = "876a5bc9fa6f05f9a3dcd9e0e4f05675f3c8fed76b61122a6ac17ddccd88ce86"
WHEEL_SHA256 = "92d45d7ad57e6d8a63becc96d14a038e17ab1919c00d771a4bbb6e6fc7aa4810"
OBS_KEYS = ("robot0_eef_pos", "robot0_eef_quat", "robot0_gripper_qpos", "object")
TASKS = {"robosuite-square": ("NutAssemblySquare", 0), "robosuite-round": ("NutAssemblyRound", 1)}
"""task -> (robosuite environment, index of its nut in robosuite's ``objects_on_pegs``)."""


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("source", type=Path, help="robosuite-1.0.1 wheel or its nut-assembly demo.hdf5")
    p.add_argument("--task", choices=sorted(TASKS), default="robosuite-square")
    p.add_argument("--work", type=Path, default=Path("/tmp/elicit-real-human"))
    p.add_argument("--out", type=Path, help="results Markdown to write")
    p.add_argument("--episodes", type=int, default=40, help="scripted base demos for training")
    p.add_argument("--contrast", type=int, default=10, help="demos per contrast set")
    p.add_argument("--conflict", default="conflict-flip-pause", help="the conflicting style")
    p.add_argument("--profile", default="cpu", help="training profile of the base policy")
    p.add_argument("--epochs", type=int, default=0, help="override the profile's epochs (0: no)")
    p.add_argument("--rollouts", type=int, default=0, help="evaluate base/naive/filtered (0: no)")
    p.add_argument("--threads", type=int, default=2, help="robosuite worker processes")
    return p.parse_args()


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def read_source(path: Path) -> bytes:
    """The demo file's bytes from the wheel or the extracted file; its hash checked."""
    if not path.exists():
        sys.exit(
            f"error: {path}: not found. Download the source first (PyPI, MIT licence):\n"
            f"  pip download --no-deps robosuite==1.0.1 -d DIR   ({SOURCE_URL})\n"
            f"and pass DIR/robosuite-1.0.1-py3-none-any.whl (or its {SOURCE_MEMBER})."
        )
    if zipfile.is_zipfile(path):
        with zipfile.ZipFile(path) as z:
            if SOURCE_MEMBER not in z.namelist():
                sys.exit(f"error: {path}: no {SOURCE_MEMBER} in this wheel (robosuite 1.0.1?)")
            data = z.read(SOURCE_MEMBER)
    else:
        data = path.read_bytes()
    if sha256(data) != SOURCE_SHA256:
        sys.exit(f"error: {path}: demo SHA-256 {sha256(data)[:12]}… is not {SOURCE_SHA256[:12]}…")
    return data


def load_demo(data: bytes) -> dict[str, Any]:
    """States, actions and recording metadata of the (single) demonstration."""
    import h5py

    with h5py.File(io.BytesIO(data), "r") as f:
        names = sorted(f["data"].keys())
        if len(names) != 1:
            sys.exit(f"error: expected one demonstration, found {names}")
        g = f["data"][names[0]]
        return {
            "name": names[0],
            "states": np.asarray(g["states"], dtype=np.float64),
            "actions": np.asarray(g["actions"], dtype=np.float64),
            "env_info": json.loads(f["data"].attrs["env_info"]),
            "date": str(f["data"].attrs["date"]),
            "repository_version": str(f["data"].attrs["repository_version"]),
        }


def set_state(env: Any, state: np.ndarray) -> None:
    """Put robosuite's simulation in a recorded ``[time, qpos, qvel]`` state."""
    sim = env.sim
    nq, nv = sim.model.nq, sim.model.nv
    if state.size != 1 + nq + nv:
        sys.exit(f"error: state has {state.size} values, this model needs 1 + {nq} + {nv}")
    sim.data.qpos[:] = state[1 : 1 + nq]
    sim.data.qvel[:] = state[1 + nq :]
    sim.forward()


def placements(states: np.ndarray) -> tuple[int, int]:
    """First step at which robosuite's check sees the square / the round nut on its peg."""
    from elicit_jax.sim.robosuite_env import make_env, spec_for

    env = make_env(spec_for("NutAssembly", OBS_KEYS), horizon=len(states) + 1)
    env.reset()
    on = np.zeros((len(states), 2), dtype=bool)
    for t, s in enumerate(states):
        set_state(env, s)
        env._check_success()
        on[t] = np.asarray(env.objects_on_pegs, dtype=bool)[:2]
    env.close()
    if not on.any(axis=0).all():
        sys.exit("error: the demonstration does not put both nuts on their pegs")
    first = on.argmax(axis=0)
    return int(first[0]), int(first[1])


def cut(task: str, states: np.ndarray) -> tuple[int, int]:
    """The [start, stop) steps of ``task``'s segment (the task's nut placed second or first)."""
    square_at, round_at = placements(states)
    if round_at >= square_at:
        sys.exit("error: this script expects the round nut placed first (the robosuite 1.0.1 demo)")
    return (round_at + 1, square_at + 1) if task == "robosuite-square" else (0, round_at + 1)


def observe(task: str, states: np.ndarray) -> dict[str, np.ndarray]:
    """robomimic's low-dim observations of each state, read in the task's environment."""
    from elicit_jax.sim.robosuite_env import ROBOMIMIC_KEY_ALIASES, make_env, spec_for

    env = make_env(spec_for(TASKS[task][0], OBS_KEYS), horizon=len(states) + 1)
    env.reset()
    out: dict[str, list[np.ndarray]] = {k: [] for k in OBS_KEYS}
    done = np.zeros(len(states), dtype=bool)
    for t, s in enumerate(states):
        set_state(env, s)
        obs = env._get_observations(force_update=True)
        for k in OBS_KEYS:
            out[k].append(np.ravel(obs[ROBOMIMIC_KEY_ALIASES.get(k, k)]).astype(np.float64))
        done[t] = bool(env._check_success())
    env.close()
    if not done[-1]:
        sys.exit(f"error: the {task} segment does not end in robosuite's success")
    return {k: np.stack(v) for k, v in out.items()}


def write_robomimic(path: Path, task: str, demo: dict[str, Any], span: tuple[int, int]) -> None:
    """The segment as a one-demo robomimic file (reward 1 at its last step: success)."""
    import h5py

    s, e = span
    states, actions = demo["states"][s:e], demo["actions"][s:e]
    obs = observe(task, states)
    env_kwargs = {
        "robots": ["Panda"],
        "control_freq": 20,
        "controller_configs": demo["env_info"]["controller_configs"],
    }
    rewards = np.zeros(e - s)
    rewards[-1] = 1.0
    tmp = path.with_suffix(".tmp.hdf5")
    with h5py.File(tmp, "w") as f:
        data = f.create_group("data")
        data.attrs["env_args"] = json.dumps(
            {"env_name": TASKS[task][0], "type": 1, "env_kwargs": env_kwargs}
        )
        data.attrs["total"] = e - s
        data.attrs["source"] = json.dumps(
            {
                "url": SOURCE_URL,
                "member": SOURCE_MEMBER,
                "sha256": SOURCE_SHA256,
                "demo": demo["name"],
                "steps": [s, e],
                "recorded": demo["date"],
                "robosuite_version": demo["repository_version"],
            }
        )
        g = data.create_group("demo_0")
        g.attrs["num_samples"] = e - s
        g["actions"], g["states"], g["rewards"] = actions, states, rewards
        g["dones"] = (rewards > 0).astype(np.int64)
        for k, v in obs.items():
            g[f"obs/{k}"] = v
    tmp.replace(path)


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


def replay_check(task: str, human: Path) -> dict[str, Any]:
    """Open-loop replay of the human's actions in robosuite 1.5 from the segment's first
    recorded state: how far the hand drifts from the recorded one, and whether it succeeds."""
    import h5py

    from elicit_jax.sim.robosuite_env import make_env, spec_for

    with h5py.File(human, "r") as f:
        g = f["data/demo_0"]
        states, actions = g["states"][:], g["actions"][:]
        eef = g["obs/robot0_eef_pos"][:]
    env = make_env(spec_for(TASKS[task][0], OBS_KEYS), horizon=len(states) + 1)
    env.reset()
    set_state(env, states[0])
    err, ok = [], False
    for t in range(len(actions) - 1):
        obs, *_ = env.step(actions[t])
        err.append(float(np.linalg.norm(obs["robot0_eef_pos"] - eef[t + 1])))
        ok = ok or bool(env._check_success())
    env.close()
    return {"err_50": max(err[:50]), "err_max": max(err), "success": ok}


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


def report(args: argparse.Namespace, work: Path, prep: dict[str, Any], cmd: str) -> str:
    """The results Markdown."""
    thr = json.loads((work / "thresholds.json").read_text())
    lam, eta, rep = thr["lambda"], thr["eta"], thr["report"]
    trust = rep["trust"]
    fitted = per_operator(work / "scores_fitted.parquet", lam, eta)
    plam, peta = PAPER_THRESHOLDS[args.task]
    paper = per_operator(work / "scores_fitted.parquet", plam, peta)
    prof, novel = human_profile(work / "human_scores.parquet", lam, eta)
    rp = prep["replay"]
    s, e = prep["span"]
    h = fitted["human"]
    verdict = "rejected" if h["rejected"] else "accepted"
    loo = "n/a" if rep.get("loo_accuracy") is None else f"{rep['loo_accuracy']:.2f}"
    lines = [
        f"# Real human demonstration on `{args.task}` ({TASKS[args.task][0]})",
        "",
        f"Command: `{cmd}`",
        "",
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
        lines += ["", "## Rollouts (same seeded initial states)", "",
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
    return "\n".join(lines) + "\n"


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
    text = report(args, work, prep, cmd)
    print(text)
    if args.out:
        args.out.write_text(text)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
