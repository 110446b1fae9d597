"""``elicit-jax evaluate``: success of policies over the same seeded initial states.

Every policy (each seed of each run, each requested checkpoint) rolls out from the same
``rollouts`` initial states, so policies compare pairwise. Output: one Parquet row per
rollout (policy, seed, checkpoint, rollout index, initial-state seed, success, steps to
success, trajectory length, return, whether the physics diverged) with a summary in the
header: success rate per policy
as mean (std) over training seeds, and the mean trajectory length. ``select="best"`` keeps,
for each training seed, the checkpoint with the highest success rate (robomimic reports the
best checkpoint).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.errors import ElicitError
from elicit_jax.stats import sample_std

if TYPE_CHECKING:
    from elicit_jax.policy.base import Policy

ROLLOUTS_KIND = "rollouts"
ROLLOUTS_SCHEMA_VERSION = 1
EVAL_SEED_BASE = 1_000_000_000
"""Initial-state seeds of evaluation, far from those of collection (``seed * 100000 + i``)."""
BACKENDS = ("auto", "mjx", "mujoco", "robosuite")


@dataclasses.dataclass(frozen=True)
class EvalConfig:
    """Settings of an evaluation.

    Attributes:
      task: task name.
      rollouts: rollouts per policy (the paper: 50).
      seed: picks the set of initial states (``EVAL_SEED_BASE + seed * 100000 + i``).
      backend: ``auto`` (C MuJoCo when JAX runs on CPU, else MJX), ``mjx`` or ``mujoco``.
      horizon: control steps per rollout (0: the task's).
      checkpoints: ``best``, ``final``, ``all`` (every saved epoch and best) or epoch numbers.
      select: ``all`` (summarise every checkpoint) or ``best`` (best checkpoint per seed).
      threads: C MuJoCo threads (0: one per CPU).
      env_from: a robomimic ``.hdf5`` whose ``env_args`` name the robosuite environment to
        evaluate in (instead of ``task``); the policies' observation keys must match it.
      workers: robosuite worker processes, one environment each (0: one per CPU).
    """

    task: str = "square-nut"
    rollouts: int = 50
    seed: int = 0
    backend: str = "auto"
    horizon: int = 0
    checkpoints: tuple[str, ...] = ("best",)
    select: str = "all"
    threads: int = 0
    env_from: str = ""
    workers: int = 0

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise ElicitError(f"unknown backend {self.backend!r}; choose {', '.join(BACKENDS)}")
        if self.select not in ("all", "best"):
            raise ElicitError(f"--select must be 'all' or 'best', got {self.select!r}")
        if self.rollouts < 1:
            raise ElicitError(f"--rollouts must be at least 1, got {self.rollouts}")
        for flag, value in (("--horizon", self.horizon), ("--threads", self.threads)):
            if value < 0:
                raise ElicitError(f"{flag} must be >= 0 (0: the default), got {value}")


def eval_seeds(config: EvalConfig) -> np.ndarray:
    """(rollouts,) initial-state seeds of an evaluation."""
    return EVAL_SEED_BASE + config.seed * 100_000 + np.arange(config.rollouts)


def resolve_backend(backend: str, task: str | None = None, env_from: str = "") -> str:
    """``mjx``, ``mujoco`` or ``robosuite`` for a requested backend and task (``auto``: C
    MuJoCo on CPU-only JAX; robosuite tasks and ``env_from`` always run on robosuite).

    Raises:
      ElicitError: a robosuite task on another backend, or the reverse.
    """
    on_robosuite = bool(env_from) or (task is not None and is_robosuite_task(task))
    if on_robosuite and backend not in ("auto", "robosuite"):
        raise ElicitError(f"robosuite environments run on --backend robosuite, not {backend!r}")
    if on_robosuite or backend == "robosuite":
        if not on_robosuite:
            raise ElicitError(f"task '{task}' does not run on robosuite")
        return "robosuite"
    if backend != "auto":
        return backend
    import jax

    return "mujoco" if jax.default_backend() == "cpu" else "mjx"


def is_robosuite_task(name: str) -> bool:
    """Whether task ``name`` plays in robosuite (built without importing robosuite)."""
    from elicit_jax.sim.env import make_task

    return getattr(make_task(name), "backend", "") == "robosuite"


def rollout_mujoco_policy(
    task: Any,
    policy: Policy,
    seeds: np.ndarray,
    horizon: int,
    threads: int = 0,
    record_states: bool = False,
    action_noise: float = 0.0,
) -> dict[str, np.ndarray]:
    """Roll out ``policy`` on C MuJoCo: one batched policy call per control step.

    See :func:`elicit_jax.sim.rollout_mujoco.rollout_policy`.

    Returns:
      dict of ``success (B,)``, ``steps_to_success (B,)`` (horizon when never), ``ret (B,)``,
      ``final_obs (B, 23)``, ``unstable (B,)`` (the physics diverged; frozen, not a success);
      with ``record_states`` also ``states (B, horizon, 23)`` and ``state_mask (B, horizon)``.
    """
    from elicit_jax.policy.base import jitted_act
    from elicit_jax.sim.rollout_mujoco import rollout_policy

    return rollout_policy(
        task, jitted_act(), policy, seeds, horizon, threads or None, record_states, action_noise
    )


@dataclasses.dataclass(frozen=True)
class PolicyRef:
    """One policy to evaluate: a label, a checkpoint directory, a seed, a checkpoint."""

    label: str
    path: Path
    seed: int
    checkpoint: str


def expand_policies(specs: Sequence[str | Path], checkpoints: Sequence[str]) -> list[PolicyRef]:
    """Policy references for ``LABEL=PATH`` or ``PATH`` specs (every seed of a run).

    Raises:
      ElicitError: a missing run, or a checkpoint no seed has.
    """
    from elicit_jax.policy.checkpoint import list_checkpoints, seed_dirs

    refs = []
    for spec in specs:
        text = str(spec)
        label, _, path_text = text.rpartition("=") if "=" in text else ("", "", text)
        path = Path(path_text)
        label = label or path.name
        avail = list_checkpoints(path)
        for seed, seed_dir in sorted(seed_dirs(path).items()):
            names = [str(c) for c in avail[seed]]
            wanted: list[str] = []
            for c in checkpoints:
                if c == "all":
                    wanted += names
                elif c == "final" or c in names:
                    wanted.append(c)
                else:
                    raise ElicitError(f"seed {seed} has no checkpoint {c!r} (has {names})", path)
            for c in dict.fromkeys(wanted):
                refs.append(PolicyRef(label, seed_dir, seed, c))
    if not refs:
        raise ElicitError("no policies to evaluate")
    return refs


def evaluate_refs(
    refs: Sequence[PolicyRef],
    config: EvalConfig,
    progress: Callable[[PolicyRef, float], None] | None = None,
    trajectories: Any = None,
) -> Any:
    """Roll out every policy reference; returns the per-rollout ``pandas.DataFrame``.

    With ``trajectories`` (a :class:`~elicit_jax.sim.trajectories.TrajectoryConfig`) the
    rollouts run with its exploration noise and every step is recorded (C MuJoCo or robosuite).
    """
    import pandas as pd

    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.registry import task_entry
    from elicit_jax.sim.rollout_mjx import rollout_mjx

    backend = resolve_backend(config.backend, config.task, config.env_from)
    seeds = eval_seeds(config)
    if trajectories is not None:
        from elicit_jax.sim.trajectories import steps_frame, write_trajectories

        if backend == "mjx":
            raise ElicitError("--trajectories records on C MuJoCo or robosuite, not MJX")
    if backend == "robosuite":
        return _evaluate_robosuite(refs, config, seeds, progress, trajectories)
    task = make_task(config.task)
    horizon = config.horizon or task.config.horizon
    frames, steps = [], []
    for ref in refs:
        policy = load_policy(ref.path, ref.checkpoint, task=task_entry(task.name)).policy
        if backend == "mjx":
            out = rollout_mjx(task, policy, seeds, horizon)
        else:
            noise = 0.0 if trajectories is None else trajectories.action_noise
            record = trajectories is not None
            out = rollout_mujoco_policy(task, policy, seeds, horizon, config.threads, record, noise)
            if record:
                steps.append(steps_frame(ref, seeds, out))
        frames.append(rollout_frame(ref, seeds, out, horizon))
        if progress is not None:
            progress(ref, float(np.mean(out["success"])))
    if trajectories is not None:
        header = {"config": dataclasses.asdict(config), "task": config.task, "seed": config.seed}
        write_trajectories(steps, trajectories, header)
    return pd.concat(frames, ignore_index=True)


def _evaluate_robosuite(
    refs: Sequence[PolicyRef],
    config: EvalConfig,
    seeds: np.ndarray,
    progress: Callable[[PolicyRef, float], None] | None,
    trajectories: Any,
) -> Any:
    """:func:`evaluate_refs` on robosuite workers (recording steps with ``trajectories``)."""
    import pandas as pd

    from elicit_jax.sim.evaluate_robosuite import evaluate_refs_robosuite

    noise = 0.0 if trajectories is None else trajectories.action_noise
    record = trajectories is not None
    results, horizon, _ = evaluate_refs_robosuite(refs, config, seeds, progress, record, noise)
    if record:
        from elicit_jax.sim.trajectories import steps_frame, write_trajectories

        steps = [steps_frame(ref, seeds, out) for ref, out in results]
        header = {"config": dataclasses.asdict(config), "task": config.task, "seed": config.seed}
        write_trajectories(steps, trajectories, header)
    return pd.concat(
        [rollout_frame(ref, seeds, out, horizon) for ref, out in results], ignore_index=True
    )


def rollout_frame(ref: PolicyRef, seeds: np.ndarray, out: dict, horizon: int) -> Any:
    """Per-rollout rows of one policy."""
    import pandas as pd

    success = np.asarray(out["success"], bool)
    steps = np.asarray(out["steps_to_success"], np.int32)
    return pd.DataFrame(
        {
            "policy": ref.label,
            "path": str(ref.path),
            "seed": np.int32(ref.seed),
            "checkpoint": ref.checkpoint,
            "rollout": np.arange(len(seeds), dtype=np.int32),
            "init_seed": np.asarray(seeds, np.int64),
            "success": success,
            "steps_to_success": np.where(success, steps, -1).astype(np.int32),
            "length": np.where(success, steps, horizon).astype(np.int32),
            "ret": np.asarray(out["ret"], np.float32),
            "unstable": np.asarray(out["unstable"], bool),
        }
    )


def summarize(rollouts: Any, select: str = "all") -> Any:
    """Summary per policy (and checkpoint unless ``select='best'``).

    A training seed is one checkpoint directory (``path``); runs given the same label pool
    their seeds. Columns: policy, checkpoint, n_seeds, success_mean, success_std (over
    training seeds, ddof 1 as in the study tables, 0.0 for one seed; success in percent),
    mean_length (over all its rollouts), unstable (rollouts whose physics diverged).
    """
    import pandas as pd

    if "path" not in rollouts:
        rollouts = rollouts.assign(path=rollouts["seed"].astype(str))
    per = (
        rollouts.groupby(["policy", "path", "seed", "checkpoint"], sort=False)
        .agg(
            success=("success", "mean"),
            length=("length", "mean"),
            unstable=("unstable", "sum"),
        )
        .reset_index()
    )
    per["success"] *= 100.0
    if select == "best":
        idx = per.groupby(["policy", "path"], sort=False)["success"].idxmax()
        per = per.loc[idx].copy()
        keys = ["policy"]
    else:
        keys = ["policy", "checkpoint"]
    rows = []
    for key, g in per.groupby(keys, sort=False):
        key = key if isinstance(key, tuple) else (key,)
        row = dict(zip(keys, key, strict=True))
        if select == "best":
            row["checkpoint"] = ",".join(
                f"s{s}:{c}" for s, c in zip(g.seed, g.checkpoint, strict=True)
            )
        row.update(
            n_seeds=len(g),
            success_mean=float(g.success.mean()),
            success_std=sample_std(g.success),
            mean_length=float(g.length.mean()),
            unstable=int(g.unstable.sum()),
        )
        rows.append(row)
    return pd.DataFrame(rows)


def evaluate_policies(
    policies: Sequence[str | Path],
    config: EvalConfig,
    out: str | Path | None = None,
    progress: Callable[[PolicyRef, float], None] | None = None,
    trajectories: Any = None,
) -> tuple[Any, Any]:
    """Evaluate policies (``PATH`` or ``LABEL=PATH`` of training runs) on ``config.task``.

    Args:
      policies: run or seed directories; a label groups several runs as seeds of one policy.
      config: the evaluation settings.
      out: optional path of the per-rollout Parquet artifact.
      progress: optional callable ``progress(ref, success_rate)`` after each policy.
      trajectories: optional :class:`~elicit_jax.sim.trajectories.TrajectoryConfig`: also
        record every step (state, action taken, outcome), with its exploration noise.

    Returns:
      ``(rollouts, summary)`` data frames.
    """
    refs = expand_policies(policies, config.checkpoints)
    rollouts = evaluate_refs(refs, config, progress, trajectories)
    summary = summarize(rollouts, config.select)
    if out is not None:
        write_rollouts(out, rollouts, summary, config, refs)
    return rollouts, summary


def write_rollouts(
    path: str | Path, rollouts: Any, summary: Any, config: EvalConfig, refs: Sequence[PolicyRef]
) -> None:
    """Write the per-rollout table with the summary in its header."""
    import pyarrow as pa

    from elicit_jax.artifact import make_header, write_parquet

    inputs = {
        f"{r.label}/seed{r.seed}": r.path
        for r in dict.fromkeys(PolicyRef(r.label, r.path, r.seed, "") for r in refs)
    }
    if config.env_from:
        inputs["env_from"] = Path(config.env_from)
    header = make_header(
        ROLLOUTS_KIND,
        ROLLOUTS_SCHEMA_VERSION,
        config=dataclasses.asdict(config),
        inputs=inputs,
        seed=config.seed,
        task=f"env-from:{Path(config.env_from).name}" if config.env_from else config.task,
        backend=resolve_backend(config.backend, config.task, config.env_from),
        n_rows=len(rollouts),
        summary=summary.to_dict(orient="records"),
        training_seeds=sorted({int(s) for s in rollouts["seed"]}),
        eval_seeds=sorted({int(s) for s in rollouts["eval_seed"]})
        if "eval_seed" in rollouts
        else [config.seed],
    )
    write_parquet(path, pa.Table.from_pandas(rollouts, preserve_index=False), header)
