"""Per-episode quality metrics with outlier flags (``elicit-jax quality``; ``filter --method
quality`` drops the flagged episodes).

Metrics of one episode with actions ``a_0..a_{T-1}`` (motion dims = every action dim but the
gripper's; states standardised per dim over the whole file):

* ``duration``: T, its steps.
* ``jerk``: mean squared second difference of the motion actions,
  ``mean_t ||a_{t+1} − 2a_t + a_{t−1}||²`` (for velocity or delta-pose actions, the motion's
  jerk up to the control period); 0 for T < 3.
* ``idle_fraction``: share of steps whose motion action has max-norm below ``idle_eps``.
* ``spikes``: steps whose motion action jumps from the previous step by more than
  ``spike_jump`` in some dim (the DROID action-spike audit's kind of glitch).
* ``gripper_chatter``: sign changes of the gripper action among steps with
  ``|gripper| > gripper_deadband`` (open-close-open flicker).
* ``action_variance`` (Belkhale et al., 2023, "Data Quality in Imitation Learning": action
  divergence): mean over its steps of the mean squared difference between its action and the
  actions of the ``k`` nearest states of *other* episodes.
* ``state_distance`` (ibid.: state similarity, as a distance): mean over its steps of the
  distance to the nearest state of another episode.

Neighbours are searched among at most ``max_reference`` pairs of the file (a seeded sample).
Each metric gets a robust z-score over the file's episodes, ``0.6745 (x − median) / MAD``
(Iglewicz & Hoaglin; when the MAD is 0, ``(x − median) / (1.2533 · mean absolute deviation)``,
and 0 when every value is equal); an episode is flagged on a metric when ``z ≥ z_threshold``
(both tails for ``duration``: too short or too long; the high tail for the others).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.curation.episodes import EpisodeScores, episode_table
from elicit_jax.errors import ElicitError

QUALITY_KIND = "quality"
SCHEMA_VERSION = 1
METRICS = (
    "duration",
    "jerk",
    "idle_fraction",
    "spikes",
    "gripper_chatter",
    "action_variance",
    "state_distance",
)
TWO_SIDED = ("duration",)


@dataclasses.dataclass(frozen=True)
class QualityConfig:
    """Quality metric settings.

    Attributes:
      z_threshold: robust z-score at or above which a metric flags an episode.
      idle_eps: max-norm below which a motion action counts as idle.
      spike_jump: per-dim jump between consecutive motion actions that counts as a spike.
      gripper_dim: the gripper's action dim (-1: the last; None: no gripper).
      gripper_deadband: gripper actions within ±this have no sign.
      k: nearest states for the action variance.
      max_reference: at most this many pairs are searched for neighbours (seeded sample).
      seed: seed of that sample.
    """

    z_threshold: float = 3.5
    idle_eps: float = 0.02
    spike_jump: float = 0.5
    gripper_dim: int | None = -1
    gripper_deadband: float = 0.1
    k: int = 5
    max_reference: int = 4096
    seed: int = 0

    def __post_init__(self) -> None:
        flags = {"z_threshold": "--z", "idle_eps": "--idle-eps", "spike_jump": "--spike-jump"}
        for name in ("z_threshold", "idle_eps", "spike_jump", "gripper_deadband"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                flag = f" ({flags[name]})" if name in flags else ""
                raise ElicitError(f"quality: {name}{flag} must be a positive number, got {v:g}")
        if self.k < 1 or self.max_reference < 2:
            raise ElicitError("quality: k must be >= 1 and max_reference >= 2")


def _dims(action_dim: int, config: QualityConfig) -> tuple[np.ndarray, int | None]:
    grip = config.gripper_dim
    if grip is not None:
        if not -action_dim <= grip < action_dim or action_dim < 2:
            raise ElicitError(f"quality: gripper_dim {grip} is not a dim of {action_dim}-D actions")
        grip %= action_dim
    motion = np.asarray([d for d in range(action_dim) if d != grip])
    return motion, grip


def episode_metrics(action: np.ndarray, config: QualityConfig) -> dict[str, float]:
    """The per-episode metrics that need only its own actions ``(T, A)``."""
    motion, grip = _dims(action.shape[1], config)
    m = np.asarray(action, np.float64)[:, motion]
    jerk = float(np.mean(np.sum(np.diff(m, 2, axis=0) ** 2, axis=1))) if len(m) >= 3 else 0.0
    jumps = np.abs(np.diff(m, axis=0)).max(axis=1) if len(m) >= 2 else np.zeros(0)
    chatter = 0
    if grip is not None:
        g = action[:, grip]
        signs = np.sign(g[np.abs(g) > config.gripper_deadband])
        chatter = int(np.count_nonzero(np.diff(signs)))
    return {
        "duration": float(len(m)),
        "jerk": jerk,
        "idle_fraction": float(np.mean(np.abs(m).max(axis=1) < config.idle_eps)),
        "spikes": float(np.count_nonzero(jumps > config.spike_jump)),
        "gripper_chatter": float(chatter),
    }


def neighbour_metrics(
    obs: np.ndarray, action: np.ndarray, index: np.ndarray, config: QualityConfig
) -> tuple[np.ndarray, np.ndarray]:
    """Per-pair ``(action variance, state distance)`` against the other episodes' pairs."""
    from elicit_jax.curation.deminf import standardise

    s = standardise(obs).astype(np.float64)
    a = np.asarray(action, np.float64)
    ref = np.arange(len(s))
    if len(ref) > config.max_reference:
        rng = np.random.default_rng(config.seed)
        ref = np.sort(rng.choice(len(s), config.max_reference, replace=False))
    var = np.zeros(len(s))
    dist = np.zeros(len(s))
    sq_ref = np.sum(s[ref] ** 2, axis=1)
    for lo in range(0, len(s), 1024):
        q = s[lo : lo + 1024]
        d2 = np.sum(q**2, axis=1)[:, None] - 2 * q @ s[ref].T + sq_ref[None]
        d2 = np.maximum(d2, 0.0)
        d2[index[lo : lo + 1024, None] == index[ref][None]] = np.inf
        k = min(config.k, len(ref))
        nn = np.argsort(d2, axis=1, kind="stable")[:, :k]
        near = np.take_along_axis(d2, nn, axis=1)
        if not np.isfinite(near[:, 0]).all():
            raise ElicitError("quality: action variance needs at least two episodes")
        ok = np.isfinite(near)
        diff = np.sum((a[ref][nn] - a[lo : lo + 1024, None]) ** 2, axis=-1)
        var[lo : lo + 1024] = np.sum(np.where(ok, diff, 0.0), 1) / ok.sum(1) / a.shape[1]
        dist[lo : lo + 1024] = np.sqrt(near[:, 0])
    return var, dist


def robust_z(x: np.ndarray) -> np.ndarray:
    """``0.6745 (x − median) / MAD``; with MAD 0, ``(x − median) / (1.2533 · mean absolute
    deviation)``; all zeros when every value is equal."""
    x = np.asarray(x, np.float64)
    med = np.median(x)
    mad = np.median(np.abs(x - med))
    if mad > 0:
        return 0.6745 * (x - med) / mad
    mean_ad = np.mean(np.abs(x - med))
    return np.zeros_like(x) if mean_ad == 0 else (x - med) / (1.2533 * mean_ad)


@dataclasses.dataclass(frozen=True)
class Quality:
    """Per-episode metrics, z-scores and flags of a demos file.

    Attributes:
      episode: (E,) ids; operator: (E,); metrics / z / flags: per metric name, (E,) each.
      flagged: (E,) any flag; reason: (E,) one line per episode ('' when not flagged).
    """

    episode: np.ndarray
    operator: np.ndarray
    metrics: dict[str, np.ndarray]
    z: dict[str, np.ndarray]
    flags: dict[str, np.ndarray]
    flagged: np.ndarray
    reason: list[str]


def _reason(i: int, metrics: dict, z: dict, flags: dict, thr: float) -> str:
    parts = [
        f"{name} {metrics[name][i]:.3g} (robust z {z[name][i]:+.1f}, |z| >= {thr:g})"
        for name in METRICS
        if flags[name][i]
    ]
    return "; ".join(parts)


def quality_metrics(demos: Any, config: QualityConfig = QualityConfig()) -> Quality:
    """Quality metrics, robust z-scores and outlier flags of every episode of ``demos``.

    Raises:
      ElicitError: fewer than 3 episodes (no outlier without a crowd).
    """
    ids, ops, length, index = episode_table(demos.episode, demos.operator)
    if len(ids) < 3:
        raise ElicitError(f"quality flags need at least 3 episodes to find outliers ({len(ids)})")
    starts = np.concatenate([[0], np.cumsum(length)[:-1]])
    per = [
        episode_metrics(demos.action[s : s + n], config)
        for s, n in zip(starts, length, strict=True)
    ]
    metrics = {name: np.asarray([p[name] for p in per]) for name in per[0]}
    var, dist = neighbour_metrics(demos.obs, demos.action, index, config)
    metrics["action_variance"] = np.bincount(index, weights=var) / length
    metrics["state_distance"] = np.bincount(index, weights=dist) / length
    z, flags = {}, {}
    for name in METRICS:
        if not np.isfinite(metrics[name]).all():
            raise ElicitError(f"quality: non-finite {name}")
        z[name] = robust_z(metrics[name])
        side = np.abs(z[name]) if name in TWO_SIDED else z[name]
        flags[name] = side >= config.z_threshold
    flagged = np.any(np.stack([flags[n] for n in METRICS]), axis=0)
    reason = [_reason(i, metrics, z, flags, config.z_threshold) for i in range(len(ids))]
    return Quality(ids, ops, metrics, z, flags, flagged, reason)


def quality_episode_scores(demos: Any, config: QualityConfig = QualityConfig()) -> EpisodeScores:
    """Quality as curation scores: ``−`` the largest flagging-side robust z of each episode,
    threshold ``−z_threshold`` (so the own cut drops exactly the flagged episodes)."""
    q = quality_metrics(demos, config)
    side = [np.abs(q.z[n]) if n in TWO_SIDED else q.z[n] for n in METRICS]
    score = -np.max(np.stack(side), axis=0)
    _, _, length, _ = episode_table(demos.episode, demos.operator)
    report = {"flagged": int(q.flagged.sum()), "flags": {n: int(q.flags[n].sum()) for n in METRICS}}
    return EpisodeScores(
        "quality", q.episode, q.operator, length, score, -config.z_threshold, report
    )


def write_quality(path: str | Path, q: Quality, *, config: QualityConfig, inputs: dict) -> None:
    """Write a ``quality`` artifact: one row per episode (metrics, ``<metric>_z``,
    ``<metric>_flag``, ``flagged``, ``reason``)."""
    import pyarrow as pa

    from elicit_jax.artifact import make_header, write_parquet

    cols: dict[str, Any] = {
        "episode": pa.array(np.asarray(q.episode, np.int64)),
        "operator": pa.array([str(o) for o in q.operator], type=pa.string()),
    }
    for name in METRICS:
        cols[name] = pa.array(q.metrics[name])
        cols[f"{name}_z"] = pa.array(q.z[name])
        cols[f"{name}_flag"] = pa.array(q.flags[name])
    cols["flagged"] = pa.array(q.flagged)
    cols["reason"] = pa.array(q.reason, type=pa.string())
    header = make_header(
        QUALITY_KIND,
        SCHEMA_VERSION,
        config=dataclasses.asdict(config),
        inputs=inputs,
        n_episodes=len(q.episode),
        n_flagged=int(q.flagged.sum()),
        medians={n: float(np.median(q.metrics[n])) for n in METRICS},
    )
    write_parquet(path, pa.table(cols), header)


def read_quality(path: str | Path) -> Any:
    """A ``quality`` artifact as a ``pandas.DataFrame`` (one row per episode)."""
    import pyarrow.parquet as pq

    from elicit_jax.artifact import read_artifact

    read_artifact(path, QUALITY_KIND, SCHEMA_VERSION, what="quality flags")
    return pq.read_table(path).to_pandas()


def quality_file(
    demos_path: str | Path, out_path: str | Path, config: QualityConfig = QualityConfig()
) -> Quality:
    """Compute the quality flags of a demos artifact and write them to ``out_path``."""
    from elicit_jax.data.demos import read_demos

    q = quality_metrics(read_demos(demos_path), config)
    write_quality(out_path, q, config=config, inputs={"demos": demos_path})
    return q
