"""Pipeline stages of the CUPID and quality-flag curation methods: their configs, their stage
functions, and where they go in the filtering study's graph.

* ``quality/<task>/<op>`` (per task, no policy): the quality flags of one D_new as
  per-demonstration scores (kind ``episode-scores``).
* ``cupid/<task>/<model>/<op>`` (per task × model): rolls out that operator's naive policy
  (trained on D_base ∪ D_new) with exploration noise (C MuJoCo, or robosuite for its tasks),
  then scores D_new by its estimated influence on that policy's expected return.

Their scores are cut by the same ``curate`` stages as DemInf's and Demo-SCORE's: at the
method's own rule (``cupid``, ``quality``) or at the M-filter's amount (``*-matched``).
"""

from __future__ import annotations

import dataclasses
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.definition import section_fields
from elicit_jax.pipeline.graph import Stage


def resolve_quality(raw: dict[str, Any]) -> dict[str, Any]:
    """Stage config of a ``quality`` stage: task, operator and the full QualityConfig."""
    from elicit_jax.curation.quality import QualityConfig

    meta = {k: raw[k] for k in ("task", "operator") if k in raw}
    over = {k: v for k, v in raw.items() if k not in meta}
    return {
        **meta,
        "quality": dataclasses.asdict(
            QualityConfig(**section_fields(QualityConfig, over, "quality"))
        ),
    }


def resolve_cupid(raw: dict[str, Any]) -> dict[str, Any]:
    """Stage config of a ``cupid`` stage: task, model, operator, the full CupidConfig and,
    when ``[cupid] horizon`` is given, the control steps of its rollouts (0: the task's)."""
    from elicit_jax.curation.cupid import CupidConfig

    meta = {k: raw[k] for k in ("task", "model", "operator", "horizon") if k in raw}
    over = {k: v for k, v in raw.items() if k not in meta}
    return {
        **meta,
        "cupid": dataclasses.asdict(CupidConfig(**section_fields(CupidConfig, over, "cupid"))),
    }


def quality_stage(ctx: Any) -> None:
    """Quality flags of one D_new as per-demonstration scores."""
    from elicit_jax.curation.episodes import write_episode_scores
    from elicit_jax.curation.quality import QualityConfig, quality_episode_scores
    from elicit_jax.data.demos import read_demos

    cfg = QualityConfig(**ctx.config["quality"])
    scores = quality_episode_scores(read_demos(ctx.inputs["demos1"]), cfg)
    write_episode_scores(ctx.output, scores, config=dict(ctx.config), inputs=dict(ctx.inputs))


def cupid_stage(ctx: Any) -> None:
    """Roll out the naive policy with exploration noise, then CUPID-score its D_new."""
    from elicit_jax.curation.cupid import CupidConfig, cupid_file_scores
    from elicit_jax.curation.episodes import write_episode_scores
    from elicit_jax.data.demos import read_demos
    from elicit_jax.policy.checkpoint import seed_dirs
    from elicit_jax.sim.evaluate import EvalConfig, evaluate_policies, is_robosuite_task
    from elicit_jax.sim.trajectories import TrajectoryConfig

    cfg = CupidConfig(**ctx.config["cupid"])
    run = Path(ctx.inputs["policy"])
    dirs = seed_dirs(run)
    seed = min(dirs) if cfg.policy_seed is None else int(cfg.policy_seed)
    if seed not in dirs:
        raise ElicitError(f"cupid: no training seed {seed} (have {sorted(dirs)})", run)
    ev = EvalConfig(
        task=ctx.config["task"],
        rollouts=cfg.rollouts,
        seed=cfg.rollout_seed,
        horizon=int(ctx.config.get("horizon", 0)),
        backend="robosuite" if is_robosuite_task(ctx.config["task"]) else "mujoco",
        checkpoints=(cfg.checkpoint,),
    )
    with tempfile.TemporaryDirectory() as tmp:
        steps = Path(tmp) / "steps.parquet"
        traj = TrajectoryConfig(out=str(steps), action_noise=cfg.action_noise)
        rollouts, _ = evaluate_policies([f"naive={dirs[seed]}"], ev, trajectories=traj)
        ctx.console.print(
            f"  cupid rollouts: {int(rollouts['success'].sum())}/{len(rollouts)} succeeded "
            f"(action noise {cfg.action_noise:g})"
        )
        new, base = read_demos(ctx.inputs["demos1"]), read_demos(ctx.inputs["demos0"])
        scores = cupid_file_scores(run, steps, new, base, cfg)
    inputs = {"policy": run / "artifact.json", "demos0": ctx.inputs["demos0"]}
    inputs["demos1"] = ctx.inputs["demos1"]
    write_episode_scores(ctx.output, scores, config=dict(ctx.config), inputs=inputs)


def operator_stages(
    spec: Any, task: Any, kind: str, label: str, resolve: Callable, over_base: bool = False
) -> list[Stage]:
    """Per-demonstration scores of each D_new of a task that need no policy (``deminf``:
    estimated over D_base ∪ D_new, ``over_base``; ``quality``): one ``kind`` stage per operator,
    configured by the section of that name, when a method of that kind is chosen."""
    if not any(m.startswith(kind) for m in spec.methods):
        return []
    t = task.name
    base = {"demos0": f"collect/{t}/base"} if over_base else {}
    return [
        Stage(
            id=f"{kind}/{t}/{op}",
            kind=kind,
            output=f"curation/{t}/{kind}-{op}.parquet",
            config=resolve(kind, {**spec.section(kind), "task": t, "operator": op}),
            inputs={**base, "demos1": f"collect/{t}/new/{op}"},
            label=f"{label} {t} D_new of {op}",
        )
        for op in task.operators
    ]


def cupid_plan(spec: Any, task: Any, model: str, op: str, naive: Stage, resolve: Callable) -> Stage:
    """The ``cupid`` stage of one task × model × operator (rollouts of its naive policy)."""
    t = task.name
    raw = {**spec.section("cupid"), "task": t, "model": model, "operator": op}
    raw.setdefault("policy_seed", spec.seeds[0])
    return Stage(
        id=f"cupid/{t}/{model}/{op}",
        kind="cupid",
        output=f"curation/{t}/{model}/cupid-{op}.parquet",
        config=resolve("cupid", raw),
        inputs={
            "policy": naive.id,
            "demos0": f"collect/{t}/base",
            "demos1": f"collect/{t}/new/{op}",
        },
        label=f"cupid {t} {model} D_new of {op} (noisy rollouts of its naive policy)",
    )


def per_demo_source(method: str, t: str, op: str, stages: Mapping[str, Stage | None]) -> str:
    """The stage whose per-demonstration scores a curation method cuts."""
    base = method.removesuffix("-matched")
    if base == "deminf":
        return f"deminf/{t}/{op}"
    if base == "quality":
        return f"quality/{t}/{op}"
    stage = stages.get(base)
    if stage is None:
        raise ElicitError(f"no {base} stage for {t} {op}")
    return stage.id
