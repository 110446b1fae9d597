"""Score a whole demonstration artifact against a base policy, streaming, in fixed chunks.

Feed-forward policies (MLP ensemble, MDN) are scored row by row: rows are grouped into chunks
of one fixed size — at most ``config.chunk_size``, balanced over the dataset so the padded
last chunk wastes little (:func:`balanced_chunk`) — and ONE jitted function, the per-pair
:func:`~elicit_jax.compat.measures.score_pair` vmapped over the chunk, scores each chunk, so
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

import dataclasses
import functools
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import jax
import numpy as np

from elicit_jax.compat.measures import ScoreConfig, score_pair
from elicit_jax.errors import ElicitError
from elicit_jax.sharding import batch_shardings, device_count, round_up
from elicit_jax.sharding import place as place_tree

SCORES_KIND = "scores"
EPISODES_KIND = "episode-scores"
SCHEMA_VERSION = 1
MIN_BUCKET = 16
_SCORE_COLUMNS = ("likelihood", "novelty", "compatibility", "incompatible")


def balanced_chunk(n_rows: int, chunk_size: int, multiple: int = 256) -> int:
    """The chunk size that covers ``n_rows`` in as many chunks as ``chunk_size`` would, with
    the least padding: ``ceil(n / ceil(n / chunk))`` rounded up to ``multiple`` (and at most
    ``chunk_size``). Scores do not depend on the chunk size; this only saves padded work."""
    if n_rows <= 0:
        return chunk_size
    n_chunks = -(-n_rows // chunk_size)
    size = -(-n_rows // n_chunks)
    return min(chunk_size, -(-size // multiple) * multiple)


def episodes_path(scores_path: str | Path) -> Path:
    """Sibling per-episode summary of a scores file: ``x.parquet`` -> ``x.episodes.parquet``."""
    p = Path(scores_path)
    return p.with_name(p.name.removesuffix(".parquet") + ".episodes.parquet")


def policy_spec(policy: Any, name: str, default: Any = None) -> Any:
    """A static spec field of a policy (on the policy or on its ``spec`` attribute)."""
    if hasattr(policy, name):
        return getattr(policy, name)
    spec = getattr(policy, "spec", None)
    return getattr(spec, name, default) if spec is not None else default


def _static(config: ScoreConfig) -> ScoreConfig:
    """The part of a config that shapes the compiled function (thresholds are arguments)."""
    return ScoreConfig(likelihood=config.likelihood, ddof=config.ddof, clip=config.clip)


@functools.partial(jax.jit, static_argnames=("config",))
def _score_rows(policy: Any, obs: Any, action: Any, lam: Any, eta: Any, config: ScoreConfig):
    """Scores of a chunk of independent pairs. obs: (C, O), action: (C, A) -> PairScores (C,)."""

    members = policy.members(obs)  # (K, C, A)
    spread = policy.spread(obs)  # (C, A) or None
    fn = functools.partial(score_pair, lambda_=lam, eta=eta, config=config)
    if spread is None:
        return jax.vmap(lambda m, a: fn(m, a), in_axes=(1, 0))(members, action)
    return jax.vmap(lambda m, a, s: fn(m, a, spread=s), in_axes=(1, 0, 0))(members, action, spread)


@functools.partial(jax.jit, static_argnames=("config",))
def _score_sequences(policy: Any, obs: Any, action: Any, lam: Any, eta: Any, config: ScoreConfig):
    """Scores of G padded episodes. obs: (G, L, O), action: (G, L, A) -> PairScores (G, L)."""

    fn = functools.partial(score_pair, lambda_=lam, eta=eta, config=config)

    def one(o, a):
        members = policy.members(o)  # (K, L, A)
        return jax.vmap(lambda m, x: fn(m, x), in_axes=(1, 0))(members, a)

    return jax.vmap(one)(obs, action)


def _to_numpy(scores: Any, n: int) -> dict[str, np.ndarray]:
    out = {k: np.asarray(getattr(scores, k))[:n] for k in _SCORE_COLUMNS}
    out["prediction"] = np.asarray(scores.mean, dtype=np.float32)[:n]
    for k in ("likelihood", "novelty", "compatibility"):
        out[k] = out[k].astype(np.float32)
    return out


def _concat(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _take(rows: dict[str, np.ndarray], sl: slice) -> dict[str, np.ndarray]:
    return {k: v[sl] for k, v in rows.items()}


def _pad(x: np.ndarray, n: int) -> np.ndarray:
    if len(x) == n:
        return x
    return np.concatenate([x, np.zeros((n - len(x), *x.shape[1:]), x.dtype)])


def _row_chunks(
    batches: Iterable[dict[str, np.ndarray]], size: int
) -> Iterator[dict[str, np.ndarray]]:
    """Regroup row batches into chunks of exactly ``size`` rows (the last may be shorter)."""
    pending: list[dict[str, np.ndarray]] = []
    count = 0
    for b in batches:
        pending.append(b)
        count += len(b["episode"])
        if count >= size:
            rows = _concat(pending)
            stop = (count // size) * size
            for s in range(0, stop, size):
                yield _take(rows, slice(s, s + size))
            pending = [_take(rows, slice(stop, None))] if stop < count else []
            count -= stop
    if count:
        yield _concat(pending)


def _episode_groups(
    batches: Iterable[dict[str, np.ndarray]], size: int
) -> Iterator[dict[str, np.ndarray]]:
    """Regroup row batches into runs of complete episodes of at least ``size`` rows."""
    pending: list[dict[str, np.ndarray]] = []
    for b in batches:
        pending.append(b)
        rows = _concat(pending)
        ep = rows["episode"]
        last = np.flatnonzero(ep != ep[-1])
        if len(last) and last[-1] + 1 >= size:
            cut = int(last[-1]) + 1
            yield _take(rows, slice(0, cut))
            pending = [_take(rows, slice(cut, None))]
        else:
            pending = [rows]
    if pending and len(pending[0]["episode"]):
        yield _concat(pending)


def _check_finite(rows: dict[str, np.ndarray], source: str) -> None:
    for name in ("obs", "action"):
        bad = ~np.isfinite(rows[name])
        if bad.any():
            r = int(np.argwhere(bad)[0][0])
            raise ElicitError(
                f"non-finite {name} value at episode {rows['episode'][r]}, step {rows['step'][r]}",
                source,
            )


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
    policy: Any,
    batches: Iterable[dict[str, np.ndarray]],
    config: ScoreConfig,
    source: str = "<demos>",
    n_rows: int | None = None,
    n_devices: int | None = None,
    policy_source: str = "<policy>",
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

    Yields:
      The input columns except ``obs``/``action``, plus ``likelihood``, ``novelty``,
      ``compatibility``, ``incompatible`` (n,) and ``prediction`` (n, A).
    """
    import jax.numpy as jnp

    lam, eta = jnp.float32(config.lambda_), jnp.float32(config.eta)
    static = _static(config)
    recurrent = policy_spec(policy, "kind", "mlp") == "lstm"
    chunk = config.chunk_size
    if n_rows is not None and not recurrent:
        chunk = balanced_chunk(n_rows, chunk)
    devices = device_count(n_devices)
    place = _row_placer(devices)
    if place is not None:
        policy = place(policy, replicate=True)
        chunk = round_up(chunk, devices)
    groups = _episode_groups(batches, chunk) if recurrent else _row_chunks(batches, chunk)
    for rows in groups:
        _check_finite(rows, source)
        n = len(rows["episode"])
        if recurrent:
            scores = _score_episodes(
                policy, rows, lam, eta, static, config.chunk_size, devices, place
            )
        else:
            obs, action = _pad(rows["obs"], chunk), _pad(rows["action"], chunk)
            if place is not None:
                obs, action = place(obs), place(action)
            scores = _to_numpy(_score_rows(policy, obs, action, lam, eta, static), n)
        _check_scores(scores, rows, policy_source)
        keep = {k: v for k, v in rows.items() if k not in ("obs", "action")}
        yield {**keep, **scores}


def _row_placer(devices: int) -> Callable[..., Any] | None:
    """``place(x, replicate=False)`` putting arrays on a 1-D mesh of ``devices`` devices
    (rows split, or replicated), or ``None`` for one device (nothing is moved or copied)."""
    if devices == 1:
        return None
    rows, replicated = batch_shardings(devices)
    return lambda x, replicate=False: place_tree(x, replicated if replicate else rows)


def _score_episodes(
    policy: Any,
    rows: dict[str, np.ndarray],
    lam: Any,
    eta: Any,
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
            out = _score_sequences(policy, obs, act, lam, eta, static)
            if place is not None:
                out = jax.device_get(out)  # gather once, not once per episode
            for j, i in enumerate(part):
                results[i] = _to_numpy(_index(out, j), int(lengths[i]))
    return _concat([r for r in results if r is not None])


def _index(tree: Any, j: int) -> Any:
    return jax.tree_util.tree_map(lambda x: x[j], tree)


def check_dims(
    policy: Any, obs_dim: int, action_dim: int, source: str, obs_fields: tuple[str, ...] = ()
) -> None:
    """Raise a clear error when the policy and the demonstrations disagree on dimensions or
    (when both name them) on the observation fields."""
    p_obs, p_act = policy_spec(policy, "obs_dim"), policy_spec(policy, "action_dim")
    if p_obs is not None and int(p_obs) != int(obs_dim):
        raise ElicitError(
            f"demonstrations have obs_dim={obs_dim} but the policy expects obs_dim={p_obs}", source
        )
    if p_act is not None and int(p_act) != int(action_dim):
        raise ElicitError(
            f"demonstrations have action_dim={action_dim} but the policy predicts "
            f"action_dim={p_act}",
            source,
        )
    names = tuple(policy_spec(policy, "obs_fields", ()) or ())
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
    policy: Any, demos: Any, config: ScoreConfig, n_devices: int | None = None
) -> dict[str, np.ndarray]:
    """Score an in-memory ``Demos``; returns per-pair columns (see :func:`score_batches`)."""
    fields = tuple(f.name for f in demos.obs_fields)
    check_dims(policy, demos.obs_dim, demos.action_dim, "<demos>", fields)
    batches = demos_batches(demos)
    out = score_batches(policy, batches, config, n_rows=demos.n_steps, n_devices=n_devices)
    return _concat(list(out))


def config_dict(config: ScoreConfig) -> dict[str, Any]:
    """JSON form of a score config (``lambda_`` written as ``lambda``)."""
    d = dataclasses.asdict(config)
    d["lambda"] = d.pop("lambda_")
    return d


def config_from_dict(d: dict[str, Any]) -> ScoreConfig:
    """Inverse of :func:`config_dict`."""
    d = dict(d)
    if "lambda" in d:
        d["lambda_"] = d.pop("lambda")
    names = {f.name for f in dataclasses.fields(ScoreConfig)}
    return ScoreConfig(**{k: v for k, v in d.items() if k in names})
