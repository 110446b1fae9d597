"""``elicit-jax collect``: scripted demonstrations on C MuJoCo, successes only.

Episodes run in parallel batches. Each episode starts from a seeded initial state (seed
``seed * 100000 + attempt``) and ends at its first success (kept, like robomimic) or at the
horizon (discarded; the attempt success rate is reported).
"""

from __future__ import annotations

import contextlib
import dataclasses
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError

COLLECT_SEED_STRIDE = 100_000


@dataclasses.dataclass(frozen=True)
class CollectConfig:
    """Settings of a collection run.

    Attributes:
      task: task name.
      operator: scripted operator name.
      episodes: successful demonstrations wanted.
      seed: seed of the initial states and of the operator's randomness.
      max_attempts: give up after this many attempts (default: 4 x episodes).
      batch: environments stepped together.
      threads: C MuJoCo threads (0: one per CPU).
      require: keep only successful episodes whose measured traits say they ``conflicts``
        with the base operator's way, or show ``no-conflict`` ("" keeps every success); only
        for tasks whose operators module measures traits (see
        :func:`elicit_jax.sim.operators.episode_traits`).
    """

    task: str = "square-nut"
    operator: str = "base"
    episodes: int = 50
    seed: int = 0
    max_attempts: int = 0
    batch: int = 50
    threads: int = 0
    require: str = ""


REQUIRE = ("", "conflicts", "no-conflict")
"""Values of :attr:`CollectConfig.require`."""


@dataclasses.dataclass(frozen=True)
class CollectResult:
    """Outcome of :func:`collect_episodes`.

    Attributes:
      episodes: successful episodes as dicts of ``obs (T, 23)``, ``action (T, 7)``,
        ``reward (T,)``, ``init_seed (T,)``.
      attempts: episodes attempted.
      successes: successful attempts (>= len(episodes); extra successes are dropped).
      lengths: control steps of each kept episode.
      unverified: successful attempts left out because their measured traits did not meet
        :attr:`CollectConfig.require`.
      conflicting: kept episodes whose measured traits say they conflict (None: the task
        measures no traits).
    """

    episodes: list[dict[str, np.ndarray]]
    attempts: int
    successes: int
    lengths: list[int]
    unverified: int = 0
    conflicting: int | None = None

    @property
    def success_rate(self) -> float:
        return self.successes / max(self.attempts, 1)


def operator_rng(seed: int, operator: str) -> np.random.Generator:
    """The operator's random generator for a run: from the seed and the operator name."""
    return np.random.default_rng([int(seed), zlib.crc32(operator.encode())])


def run_batch(task: Any, operator: Any, sim: Any, seeds: np.ndarray, rng: Any) -> dict:
    """Roll out ``operator`` from the initial states ``seeds (B,)`` until success or horizon.

    Returns:
      dict with ``obs (B, H, 23)``, ``action (B, H, 7)``, ``success (B,)`` and
      ``length (B,)`` (steps up to and including the first success, else the horizon).
    """
    from elicit_jax.sim.env import ACTION_DIM

    b, h = len(seeds), task.config.horizon
    obs = sim.reset_seeds(seeds)
    operator.reset(obs, rng)
    obs_buf = np.zeros((b, h, obs.shape[1]), np.float32)
    act_buf = np.zeros((b, h, ACTION_DIM), np.float32)
    length = np.full(b, h, np.int64)
    done = np.zeros(b, bool)
    for t in range(h):
        action = operator.act(obs)
        obs_buf[:, t], act_buf[:, t] = obs, action
        obs = sim.step(action, active=~done)
        newly = sim.success & ~done
        length[newly] = t + 1
        done |= sim.success
        if done.all():
            break
    return {"obs": obs_buf, "action": act_buf, "success": done, "length": length}


def collect_episodes(config: CollectConfig, progress: Any = None) -> CollectResult:
    """Collect ``config.episodes`` successful demonstrations of a scripted operator.

    Args:
      config: the run's settings.
      progress: optional callable ``progress(kept, attempts)`` called after each batch.

    Raises:
      ElicitError: unknown task/operator, or too few successes within ``max_attempts``.
    """
    from elicit_jax.sim.env import make_task
    from elicit_jax.sim.operators import episode_traits, make_operator

    if config.episodes < 1:
        raise ElicitError(f"--episodes must be at least 1, got {config.episodes}")
    for flag, value in (("--max-attempts", config.max_attempts), ("--threads", config.threads)):
        if value < 0:
            raise ElicitError(f"{flag} must be >= 0 (0: the default), got {value}")
    task = make_task(config.task)
    operator = make_operator(task, config.operator)
    measure = episode_traits(config.task)
    _check_require(config, measure)
    rng = operator_rng(config.seed, config.operator)
    max_attempts = config.max_attempts or 4 * config.episodes
    batch = max(1, min(config.batch, config.episodes))
    kept: list[dict[str, np.ndarray]] = []
    lengths: list[int] = []
    attempts = successes = unverified = 0
    with batch_sim(task, batch, config.threads) as sim:
        batch = sim.batch
        while len(kept) < config.episodes and attempts < max_attempts:
            seeds = config.seed * COLLECT_SEED_STRIDE + attempts + np.arange(batch)
            out = run_batch(task, operator, sim, seeds, rng)
            for i in range(batch):
                if attempts >= max_attempts:
                    break
                attempts += 1
                if not out["success"][i]:
                    continue
                successes += 1
                if len(kept) < config.episodes:
                    n = int(out["length"][i])
                    obs, action = out["obs"][i, :n], out["action"][i, :n]
                    traits = trait_columns(measure, obs, action)
                    if not _meets(config.require, traits):
                        unverified += 1
                        continue
                    reward = np.zeros(n, np.float32)
                    reward[-1] = 1.0
                    kept.append(
                        {
                            "obs": obs,
                            "action": action,
                            "reward": reward,
                            "init_seed": np.full(n, seeds[i], np.int64),
                            **traits,
                        }
                    )
                    lengths.append(n)
            if progress is not None:
                progress(len(kept), attempts)
    if len(kept) < config.episodes:
        verified = f", {unverified} of them not '{config.require}'" if unverified else ""
        raise ElicitError(
            f"operator '{config.operator}' on '{config.task}' succeeded in {successes} of "
            f"{attempts} attempts{verified}; {config.episodes} demonstrations wanted "
            "(raise --max-attempts)"
        )
    conflicting = None if measure is None else sum(bool(ep["conflicts"][0]) for ep in kept)
    return CollectResult(kept, attempts, successes, lengths, unverified, conflicting)


def _check_require(config: CollectConfig, measure: Any) -> None:
    """``config.require`` is known, and the task measures traits when it is set."""
    if config.require not in REQUIRE:
        raise ElicitError(
            f"--require must be one of conflicts, no-conflict (or empty), got '{config.require}'"
        )
    if config.require and measure is None:
        raise ElicitError(
            f"--require {config.require}: task '{config.task}' measures no episode traits"
        )


def trait_columns(measure: Any, obs: np.ndarray, action: np.ndarray) -> dict[str, np.ndarray]:
    """An episode's measured traits as per-step columns (constant within the episode), or
    none when the task measures no traits.

    Args:
      measure: the task's trait measure (:func:`elicit_jax.sim.operators.episode_traits`).
      obs: (T, obs_dim) observations.
      action: (T, 7) actions.
    """
    if measure is None:
        return {}
    traits = measure(obs, action)
    n = len(obs)
    cols = {"conflicts": np.full(n, traits.conflicts)}
    for f in dataclasses.fields(traits):
        cols[f.name] = np.full(n, getattr(traits, f.name))
    return cols


def _meets(require: str, traits: dict[str, np.ndarray]) -> bool:
    """Whether an episode's trait columns meet ``require`` (:data:`REQUIRE`)."""
    if not require:
        return True
    return bool(traits["conflicts"][0]) == (require == "conflicts")


@contextlib.contextmanager
def batch_sim(task: Any, batch: int, threads: int = 0) -> Iterator[Any]:
    """``batch`` environments of ``task`` to collect in: C MuJoCo threads, or for a robosuite
    task one worker process per environment (at most one per CPU, or ``threads``)."""
    if getattr(task, "backend", "") == "robosuite":
        from elicit_jax.runtime import available_cpus
        from elicit_jax.sim.rollout_robosuite import PoolBatch, shared_pool

        yield PoolBatch(shared_pool(task.spec, min(batch, threads or available_cpus())))
        return
    from elicit_jax.sim.rollout_mujoco import BatchSim

    with BatchSim(task, batch, threads=threads or None) as sim:
        yield sim


def collect(config: CollectConfig, out: str | Path, progress: Any = None) -> CollectResult:
    """Collect demonstrations and write them as a ``demos`` Parquet artifact at ``out``."""
    from elicit_jax.data.demos import from_episodes, write_demos
    from elicit_jax.sim.env import make_task

    result = collect_episodes(config, progress=progress)
    task = make_task(config.task)
    demos = from_episodes(
        result.episodes,
        operators=config.operator,
        task=config.task,
        obs_fields=task.obs_fields,
        action_low=-1.0,
        action_high=1.0,
        provenance={
            "source": "elicit-jax collect",
            "operator": config.operator,
            "attempts": result.attempts,
            "attempt_successes": result.successes,
            "attempt_success_rate": result.success_rate,
            "task_config": dataclasses.asdict(task.config),
            **({"env_args": task.spec.env_args()} if hasattr(task, "spec") else {}),
        },
    )
    write_demos(out, demos, config=dataclasses.asdict(config), seed=config.seed)
    return result
