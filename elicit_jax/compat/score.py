"""Score a whole demonstration artifact against a base policy, streaming, in fixed chunks.

Feed-forward policies (MLP ensemble, MDN) are scored row by row: rows are grouped into chunks
of one fixed size — at most ``config.chunk_size``, balanced over the dataset so the padded
last chunk wastes little (:func:`~elicit_jax.compat.chunks.balanced_chunk`) — and ONE jitted
function (:func:`~elicit_jax.compat.scorer.score_rows`: the per-pair
:func:`~elicit_jax.compat.measures.score_pair` vmapped over the chunk) scores each chunk, so
the whole dataset compiles once. Scores do not depend on the chunk size.

Recurrent policies (LSTM) need each episode as one sequence from the zero state: complete
episodes are padded at the end to a power-of-two bucket length (causal models ignore the
padding) and scored ``chunk_size // bucket`` at a time, one compile per bucket length.

The demonstrations are read in row batches (``pyarrow`` ``iter_batches``) and the scores are
written batch by batch to a temporary Parquet file renamed into place at the end, so memory is
bounded by the chunk size whatever the dataset size.

Outputs: ``scores.parquet`` (kind ``scores``), one row per pair — ``episode``, ``operator``,
``step``, ``likelihood`` (ℓ), ``novelty`` (ν), ``compatibility`` (M), ``incompatible``
(ℓ > λ and ν < η), ``prediction`` (the ensemble-mean action, fixed-size list<float32>[A]) and the
demonstrations' ``success`` and scalar extra columns (usable as labels by ``fit-thresholds``);
and a sibling ``scores.episodes.parquet`` (kind ``episode-scores``) with one row per episode —
operator, length, incompatible pairs, fraction incompatible, mean M, mean ℓ, mean ν and the
5%-rule decision ``accepted``. Both headers hold the score config, the thresholds, and the
content hashes of the policy checkpoint and the demonstrations.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import jax
import numpy as np

from elicit_jax.compat.chunks import balanced_chunk, concat, episode_groups, pad, row_chunks
from elicit_jax.compat.measures import MC_ROWS_BUDGET, ScoreConfig
from elicit_jax.compat.scorer import (
    ScoreInputs,
    score_inputs,
    score_rows,
    score_sequences,
    static_config,
)
from elicit_jax.data.validation import check_magnitudes
from elicit_jax.errors import ElicitError
from elicit_jax.policy.kinds import model_kind
from elicit_jax.sharding import device_count, round_up, row_placer

if TYPE_CHECKING:
    from elicit_jax.data.demos import Demos
    from elicit_jax.policy.base import Policy

SCORES_KIND = "scores"
EPISODES_KIND = "episode-scores"
SCHEMA_VERSION = 1
MIN_BUCKET = 16
_SCORE_COLUMNS = ("likelihood", "novelty", "compatibility", "incompatible")


def episodes_path(scores_path: str | Path) -> Path:
    """Sibling per-episode summary of a scores file: ``x.parquet`` -> ``x.episodes.parquet``."""
    p = Path(scores_path)
    return p.with_name(p.name.removesuffix(".parquet") + ".episodes.parquet")


def _to_numpy(scores: Any, n: int) -> dict[str, np.ndarray]:
    out = {k: np.asarray(getattr(scores, k))[:n] for k in _SCORE_COLUMNS}
    out["prediction"] = np.asarray(scores.mean, dtype=np.float32)[:n]
    for k in ("likelihood", "novelty", "compatibility"):
        out[k] = out[k].astype(np.float32)
    return out


def _check_finite(rows: dict[str, np.ndarray], source: str) -> None:
    """The checks :func:`~elicit_jax.data.validation.validate` makes of obs and actions, on
    one streamed chunk: finite, and within :data:`~elicit_jax.data.validation.MAX_MAGNITUDE`
    (so a bad value in the demos is named as such, not taken for a broken checkpoint)."""

    def where(r: int) -> str:
        return f"episode {rows['episode'][r]}, step {rows['step'][r]}"

    for name in ("obs", "action"):
        bad = ~np.isfinite(rows[name])
        if bad.any():
            r, c = (int(x) for x in np.argwhere(bad.reshape(len(bad), -1))[0])
            raise ElicitError(f"non-finite {name}[{c}] value at {where(r)}", source)
    check_magnitudes({"obs": rows["obs"], "action": rows["action"]}, where, source)


def _check_scores(scores: dict[str, np.ndarray], rows: dict[str, np.ndarray], policy: str) -> None:
    """Non-finite scores (a NaN prediction would otherwise read as M = 1) are an error."""
    bad = ~(np.isfinite(scores["likelihood"]) & np.isfinite(scores["novelty"]))
    if bad.any():
        r = int(np.flatnonzero(bad)[0])
        raise ElicitError(
            f"the policy's predictions are not finite (NaN or inf) at episode "
            f"{rows['episode'][r]}, step {rows['step'][r]} ({int(bad.sum())} pairs in this "
            "chunk): the checkpoint is corrupt or its training diverged; nothing was scored",
            policy,
        )


def score_batches(
    policy: Policy,
    batches: Iterable[dict[str, np.ndarray]],
    config: ScoreConfig,
    source: str = "<demos>",
    n_rows: int | None = None,
    n_devices: int | None = None,
    policy_source: str = "<policy>",
    bounds: tuple[Any, Any] | None = None,
) -> Iterator[dict[str, np.ndarray]]:
    """Score row batches of demonstrations, yielding per-pair score batches in input order.

    With several devices each chunk is split across them along its rows
    (:mod:`elicit_jax.sharding`); the chunk size is then rounded up to a multiple of
    the device count, so the whole dataset still compiles once. Scores do not depend on it.

    Args:
      policy: a ``Policy`` (``members``, ``spread``, static ``kind``).
      batches: dicts with ``obs`` (n, O), ``action`` (n, A), ``episode`` (n,), ``operator``,
        ``step`` and any pass-through columns; episodes contiguous across batches.
      config: scoring config; ``chunk_size`` sets the compiled chunk.
      source: name used in error messages.
      n_rows: total rows, if known: feed-forward chunks are then balanced
        (:func:`balanced_chunk`) so the padded last chunk wastes little.
      n_devices: devices to shard each chunk over (default: all that JAX sees).
      policy_source: name of the policy (its checkpoint) in error messages.
      bounds: the demonstrations' recorded action bounds ``(low, high)`` (scalars or (A,)),
        the ``member-average`` clipping range unless ``config.clip`` is set.

    Yields:
      The input columns except ``obs``/``action``, plus ``likelihood``, ``novelty``,
      ``compatibility``, ``incompatible`` (n,) and ``prediction`` (n, A).
    """
    import jax.numpy as jnp

    inputs = score_inputs(policy, config, bounds, policy_source)
    static = static_config(config)
    kind = model_kind(policy.kind)
    recurrent = kind.recurrent
    if config.dropout_samples and not kind.mc_dropout:
        raise ElicitError("--dropout-samples applies to MLP ensembles only", policy_source)
    if config.dropout_samples and not policy.dropout:
        raise ElicitError(
            "--dropout-samples needs a policy trained with dropout (this one has none)",
            policy_source,
        )
    chunk = config.chunk_size
    if config.dropout_samples:  # (K * N, chunk, ...) predictions at once: bound the memory
        passes = config.dropout_samples * int(policy.n_members)
        chunk = max(1, min(chunk, MC_ROWS_BUDGET // passes))
    if n_rows is not None and not recurrent:
        chunk = balanced_chunk(n_rows, chunk)
    devices = device_count(n_devices)
    place = row_placer(devices)
    if place is not None:
        policy = place(policy, replicate=True)
        chunk = round_up(chunk, devices)
    groups = episode_groups(batches, chunk) if recurrent else row_chunks(batches, chunk)
    row0 = 0
    for rows in groups:
        _check_finite(rows, source)
        n = len(rows["episode"])
        if recurrent:
            scores = _score_episodes(
                policy, rows, inputs, static, config.chunk_size, devices, place
            )
        else:
            obs, action = pad(rows["obs"], chunk), pad(rows["action"], chunk)
            if place is not None:
                obs, action = place(obs), place(action)
            out = score_rows(policy, obs, action, inputs, jnp.int32(row0), static)
            scores = _to_numpy(out, n)
        row0 += n
        _check_scores(scores, rows, policy_source)
        keep = {k: v for k, v in rows.items() if k not in ("obs", "action")}
        yield {**keep, **scores}


def _score_episodes(
    policy: Policy,
    rows: dict[str, np.ndarray],
    inputs: ScoreInputs,
    static: ScoreConfig,
    chunk: int,
    devices: int = 1,
    place: Callable[..., Any] | None = None,
) -> dict[str, np.ndarray]:
    """Score complete episodes with a recurrent policy, padded to power-of-two buckets; with
    ``place`` (several devices) the episode groups are split across the devices."""
    ep = rows["episode"]
    starts = np.concatenate([[0], np.flatnonzero(np.diff(ep)) + 1])
    stops = np.concatenate([starts[1:], [len(ep)]])
    lengths = stops - starts
    buckets = np.maximum(MIN_BUCKET, 2 ** np.ceil(np.log2(np.maximum(lengths, 1)))).astype(int)
    results: list[dict[str, np.ndarray] | None] = [None] * len(starts)
    for length in np.unique(buckets):
        idx = np.flatnonzero(buckets == length)
        g = round_up(max(1, chunk // int(length)), devices)
        for s in range(0, len(idx), g):
            part = idx[s : s + g]
            obs = np.zeros((g, length, rows["obs"].shape[1]), np.float32)
            act = np.zeros((g, length, rows["action"].shape[1]), np.float32)
            for j, i in enumerate(part):
                obs[j, : lengths[i]] = rows["obs"][starts[i] : stops[i]]
                act[j, : lengths[i]] = rows["action"][starts[i] : stops[i]]
            if place is not None:
                obs, act = place(obs), place(act)
            out = score_sequences(policy, obs, act, inputs, static)
            if place is not None:
                out = jax.device_get(out)  # gather once, not once per episode
            for j, i in enumerate(part):
                results[i] = _to_numpy(_index(out, j), int(lengths[i]))
    return concat([r for r in results if r is not None])


def _index(tree: Any, j: int) -> Any:
    return jax.tree_util.tree_map(lambda x: x[j], tree)


def check_dims(
    policy: Policy, obs_dim: int, action_dim: int, source: str, obs_fields: tuple[str, ...] = ()
) -> None:
    """Raise a clear error when the policy and the demonstrations disagree on dimensions or
    (when both name them) on the observation fields."""
    p_obs, p_act = policy.obs_dim, policy.action_dim
    if int(p_obs) != int(obs_dim):
        raise ElicitError(
            f"demonstrations have obs_dim={obs_dim} but the policy expects obs_dim={p_obs}", source
        )
    if int(p_act) != int(action_dim):
        raise ElicitError(
            f"demonstrations have action_dim={action_dim} but the policy predicts "
            f"action_dim={p_act}",
            source,
        )
    names = tuple(policy.obs_fields)
    if obs_fields and names and tuple(obs_fields) != names:
        raise ElicitError(
            f"demonstrations have obs fields {list(obs_fields)} but the policy was trained on "
            f"{list(names)}",
            source,
        )


def demos_batches(demos: Any) -> list[dict[str, np.ndarray]]:
    """An in-memory :class:`~elicit_jax.data.demos.Demos` as one row batch."""
    rows = {
        "episode": demos.episode.astype(np.int64),
        "operator": demos.operator.astype(str).astype(object),
        "step": demos.step.astype(np.int32),
        "obs": demos.obs.astype(np.float32),
        "action": demos.action.astype(np.float32),
        "success": demos.success.astype(bool),
    }
    for k, v in demos.extra.items():
        if np.asarray(v).ndim == 1:
            rows[k] = np.asarray(v)
    return [rows]


def score_demos(
    policy: Policy, demos: Demos, config: ScoreConfig, n_devices: int | None = None
) -> dict[str, np.ndarray]:
    """Score an in-memory ``Demos``; returns per-pair columns (see :func:`score_batches`)."""
    fields = tuple(f.name for f in demos.obs_fields)
    check_dims(policy, demos.obs_dim, demos.action_dim, "<demos>", fields)
    batches = demos_batches(demos)
    out = score_batches(
        policy,
        batches,
        config,
        n_rows=demos.n_steps,
        n_devices=n_devices,
        bounds=(demos.action_low, demos.action_high),
    )
    return concat(list(out))
