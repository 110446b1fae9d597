"""The stages that make and judge policies: collect demonstrations, train on them (reusing an
identical earlier training run), evaluate every seed and checkpoint; and the file names of
stage outputs that other stages read (:data:`DEMOS_FILE`, :data:`SCORES_FILE`).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from elicit_jax.artifact import atomic_path, dumps, write_json
from elicit_jax.errors import ElicitError
from elicit_jax.pipeline.runner import StageContext

DEMOS_FILE = "demos.parquet"
SCORES_FILE = "scores.parquet"


def demos_file(path: Path) -> Path:
    """The demonstrations file of a stage output: the file itself or ``DIR/demos.parquet``."""
    return path / DEMOS_FILE if path.is_dir() else path


def collect_stage(ctx: StageContext) -> None:
    """Collect scripted demonstrations of one operator (successes only) on C MuJoCo."""
    from rich.progress import Progress

    from elicit_jax.sim.collect import CollectConfig, collect

    cfg = CollectConfig(**ctx.config["collect"])
    with Progress(console=ctx.console, transient=True) as progress:
        bar = progress.add_task(f"collect {cfg.operator}", total=cfg.episodes)
        collect(cfg, ctx.output, progress=lambda kept, _: progress.update(bar, completed=kept))


def train_stage(ctx: StageContext) -> None:
    """Train on the concatenation of the ``demos*`` inputs (D_base first); a filter output
    that kept nothing contributes nothing.

    Training is deterministic, so a run of the same config on the same training arrays
    (e.g. a filter that kept nothing, leaving D_base alone, next to the base policy) is
    copied from the run that already trained them instead of training again
    (:func:`reuse_training`).
    """
    from elicit_jax.data.demos import concat_demos, read_demos
    from elicit_jax.policy.config import TrainConfig
    from elicit_jax.policy.train import train_policy

    names = sorted(n for n in ctx.inputs if n.startswith("demos"))
    files = {n: demos_file(ctx.inputs[n]) for n in names}
    files = {n: f for n, f in files.items() if f.exists() or n == "demos0"}
    demos = concat_demos([read_demos(f) for f in files.values()])
    config = TrainConfig.from_dict(ctx.config["train"])
    if reuse_training(ctx, demos, config, files):
        return
    train_policy(demos, config, ctx.output, inputs=files, overwrite=True)
    _record_training(ctx, demos, config)


def _training_key(demos: Any, config: Any) -> str:
    import hashlib

    from elicit_jax.artifact import dumps
    from elicit_jax.policy.dataset import demos_sha256

    text = dumps(config.to_dict()) + demos_sha256(demos)
    return hashlib.sha256(text.encode()).hexdigest()


def _index_path(ctx: StageContext, key: str) -> Path:
    from elicit_jax.pipeline.runner import STATE_DIR

    return ctx.run_dir / STATE_DIR / "trainings" / f"{key}.json"


def _record_training(ctx: StageContext, demos: Any, config: Any) -> None:
    write_json(
        _index_path(ctx, _training_key(demos, config)),
        {"output": ctx.stage.output, "stage": ctx.stage.id},
    )


def reuse_training(ctx: StageContext, demos: Any, config: Any, files: Mapping[str, Path]) -> bool:
    """Copy the run of an earlier stage that trained ``config`` on the same arrays (same
    content hash) to this stage's output; False when there is none. The copy's headers name
    this stage's inputs and say where it was reused from (``reused_from``)."""
    import shutil

    from elicit_jax.artifact import content_sha256, read_json
    from elicit_jax.policy.dataset import demos_sha256

    index = _index_path(ctx, _training_key(demos, config))
    if not index.exists():
        return False
    source = ctx.run_dir / read_json(index)["output"]
    try:
        header = read_json(source / "artifact.json")
    except ElicitError:
        return False
    same_config = header.get("config") == json.loads(dumps(config.to_dict()))
    if not same_config or header.get("data_sha256") != demos_sha256(demos):
        return False
    inputs = {n: {"path": str(p), "sha256": content_sha256(p)} for n, p in files.items()}
    with atomic_path(ctx.output) as tmp:
        shutil.copytree(source, tmp)
        for head in [tmp / "artifact.json", *tmp.glob("seed*/artifact.json")]:
            data = read_json(head)
            data.update(inputs=inputs, reused_from=str(read_json(index)["output"]))
            write_json(head, data)
    ctx.console.print(f"reused the identical training run {source.name} (same config and data)")
    return True


def chosen_refs(refs: list[Any], select: Any) -> list[Any]:
    """Of ``refs``, each training seed's checkpoint chosen on the selection rollouts
    ``select`` (an evaluation frame: ``seed``, ``checkpoint``, ``success``), by the report's
    rule (:func:`elicit_jax.pipeline.evidence.choose_checkpoint`)."""
    from elicit_jax.pipeline.evidence import choose_checkpoint

    chosen = {int(s): choose_checkpoint(g)[0] for s, g in select.groupby("seed", sort=True)}
    return [r for r in refs if chosen.get(int(r.seed)) == str(r.checkpoint)]


def evaluate_stage(ctx: StageContext) -> None:
    """Roll out every seed and checkpoint of one training run on the same initial states.

    With held-out checkpoint selection, every checkpoint is rolled out on the selection seed's
    initial states and only each training seed's chosen checkpoint on the reported seed's (the
    Parquet's ``eval_seed`` column says which rollouts are which): the report's numbers need
    no more, and it saves most of the second evaluation. Rollouts are seeded per initial
    state, so the chosen checkpoint's rollouts are those it would have had beside the others.
    """
    import numpy as np
    import pandas as pd
    from rich.progress import Progress

    from elicit_jax.sim.evaluate import (
        EvalConfig,
        evaluate_refs,
        expand_policies,
        summarize,
        write_rollouts,
    )

    raw = dict(ctx.config["evaluate"])
    cfg = EvalConfig(**{**raw, "checkpoints": tuple(raw["checkpoints"])})
    label = Path(ctx.stage.output).stem
    refs = expand_policies([f"{label}={ctx.inputs['policy']}"], cfg.checkpoints)
    heldout = ctx.config.get("selection") == "heldout"
    frames = []
    with Progress(console=ctx.console, transient=True) as progress:

        def roll(refs_now: list[Any], seed: int) -> Any:
            bar = progress.add_task(
                f"evaluate {label} (evaluation seed {seed}, {cfg.rollouts} rollouts each)",
                total=len(refs_now),
            )
            frame = evaluate_refs(
                refs_now,
                dataclasses.replace(cfg, seed=seed),
                lambda ref, success: progress.advance(bar),
            )
            return frame.assign(eval_seed=np.int32(seed))

        report_refs = refs
        if heldout:  # choose on the selection seed; report only the chosen checkpoints
            frames.append(roll(refs, int(ctx.config["select_seed"])))
            report_refs = chosen_refs(refs, frames[0])
        frames.append(roll(report_refs, cfg.seed))
    rollouts = pd.concat(frames, ignore_index=True)
    reported = rollouts[rollouts["eval_seed"] == cfg.seed]
    write_rollouts(ctx.output, rollouts, summarize(reported, cfg.select), cfg, refs)
    unstable = int(rollouts["unstable"].sum())
    if unstable:
        ctx.console.print(
            f"evaluate {label}: {unstable} of {len(rollouts)} rollouts diverged (the physics "
            "became unstable) and count as failures; MuJoCo's messages are in the log"
        )
