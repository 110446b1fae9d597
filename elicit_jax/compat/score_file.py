"""Scores as artifacts: stream a demonstrations file through the scorer, write, read, summarise.

Example:
    >>> from elicit_jax.compat.score_file import score_file
    >>> config = ScoreConfig.from_preset("square-nut")
    >>> base = load_policy("runs/base")  # elicit_jax.policy.loaded
    >>> score_file(base.policy, "new.parquet", "scores.parquet", config, policy_path="runs/base")

writes ``scores.parquet`` (per pair) and ``scores.episodes.parquet`` (per episode); see
:mod:`elicit_jax.compat.score` for their columns.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.artifact import (
    HEADER_KEY,
    atomic_paths,
    dumps,
    make_header,
    read_artifact,
    refuse_overwriting_inputs,
    write_parquet,
)
from elicit_jax.compat.episode_summary import (
    EpisodeAccumulator,
    episodes_table,
)
from elicit_jax.compat.measures import ScoreConfig, config_dict
from elicit_jax.compat.score import (
    EPISODES_KIND,
    SCHEMA_VERSION,
    SCORES_KIND,
    check_dims,
    episodes_path,
    score_batches,
)
from elicit_jax.compat.thresholds import POLICY_KEY, scores_fields
from elicit_jax.data.demos import check_demos_layout
from elicit_jax.errors import ElicitError
from elicit_jax.policy.loaded import policy_sha256

if TYPE_CHECKING:
    from elicit_jax.policy.base import Policy

_CORE = ("episode", "operator", "step", "obs", "action")
ROW_GROUP = 1 << 17  # rows per written Parquet row group (bounds the writer's buffer)
#: ``progress(total)`` -> a context yielding ``advance(n)`` (n more pairs scored).
ScoreProgress = Callable[[int], AbstractContextManager[Callable[[int], None]]]


def _no_op(n: int) -> None:
    """``advance`` when nothing shows progress."""


@dataclasses.dataclass(frozen=True)
class ScoreResult:
    """What :func:`score_file` wrote: paths and the per-episode summary columns."""

    scores_path: Path
    episodes_path: Path
    n_pairs: int
    episodes: Mapping[str, np.ndarray]


def _passthrough(header: Mapping[str, Any], schema: Any) -> list[str]:
    import pyarrow as pa

    names = ["success"] if "success" in schema.names else []
    for k in header.get("extra_columns", []):
        if k not in schema.names or k in _CORE:
            continue
        kind = schema.field(k).type
        if not (pa.types.is_list(kind) or pa.types.is_fixed_size_list(kind)):
            names.append(k)
    return names


def read_demo_batches(
    path: str | Path, batch_rows: int, columns: Sequence[str]
) -> Iterator[dict[str, np.ndarray]]:
    """Stream a demonstrations Parquet file as numpy row batches (obs/action as 2-D)."""
    import pyarrow.parquet as pq

    pf = pq.ParquetFile(path)
    for rb in pf.iter_batches(batch_size=batch_rows, columns=list(columns)):
        out: dict[str, np.ndarray] = {}
        for name in columns:
            col = rb.column(name)
            if name in ("obs", "action"):
                width = col.type.list_size
                out[name] = col.flatten().to_numpy(zero_copy_only=False).astype(np.float32)
                out[name] = out[name].reshape(-1, width)
            elif name == "operator":
                out[name] = np.asarray(col.to_pylist(), dtype=object)
            else:
                out[name] = col.to_numpy(zero_copy_only=False)
        yield out


def _arrow_table(batch: Mapping[str, np.ndarray], schema: Any) -> Any:
    import pyarrow as pa

    cols = []
    for field in schema:
        v = batch[field.name]
        if pa.types.is_fixed_size_list(field.type):
            arr = np.ascontiguousarray(v, dtype=np.float32)
            cols.append(pa.FixedSizeListArray.from_arrays(pa.array(arr.reshape(-1)), arr.shape[1]))
        elif field.name == "operator":
            cols.append(pa.array([str(x) for x in v], type=pa.string()))
        else:
            cols.append(pa.array(np.asarray(v), type=field.type))
    return pa.Table.from_arrays(cols, schema=schema)


def _scores_schema(action_dim: int, passthrough: Sequence[tuple[str, Any]]) -> Any:
    import pyarrow as pa

    fields = [
        pa.field("episode", pa.int64()),
        pa.field("operator", pa.string()),
        pa.field("step", pa.int32()),
        pa.field("likelihood", pa.float32()),
        pa.field("novelty", pa.float32()),
        pa.field("compatibility", pa.float32()),
        pa.field("incompatible", pa.bool_()),
        pa.field("prediction", pa.list_(pa.float32(), action_dim)),
    ]
    fields += [pa.field(n, t) for n, t in passthrough]
    return pa.schema(fields)


def score_file(
    policy: Policy,
    demos_path: str | Path,
    out_path: str | Path,
    config: ScoreConfig,
    *,
    policy_path: str | Path | None = None,
    policy_info: Mapping[str, Any] | None = None,
    progress: ScoreProgress | None = None,
) -> ScoreResult:
    """Score every pair of a demonstrations artifact, streaming; write scores + episode summary.

    Args:
      policy: the base ``Policy``.
      demos_path: a ``demos`` Parquet artifact.
      out_path: where to write the per-pair scores (the per-episode summary goes to
        :func:`~elicit_jax.compat.score.episodes_path` of it).
      config: scoring config (thresholds, likelihood kind, ddof, chunk size); where its
        thresholds came from is recorded too (:func:`~elicit_jax.compat.thresholds.scores_fields`).
      policy_path: the checkpoint the policy was loaded from (its hash goes in the header).
      policy_info: how it was loaded (e.g. ``{"which": "best", "seed": 0}``), recorded too.
      progress: ``progress(total_pairs)`` opens a context yielding ``advance(n)``, called as
        pairs are scored (:func:`elicit_jax.compat.show.scoring_bar` draws a bar).

    Returns:
      A :class:`ScoreResult`.
    """
    demos_path, out_path = Path(demos_path), Path(out_path)
    refuse_overwriting_inputs([out_path, episodes_path(out_path)], [demos_path, policy_path])
    header, pf = _open_demos(demos_path, policy)
    passthrough = _passthrough(header, pf.schema_arrow)
    action_dim = pf.schema_arrow.field("action").type.list_size
    schema = _scores_schema(action_dim, [(n, pf.schema_arrow.field(n).type) for n in passthrough])
    inputs = {"demos": demos_path} | ({"policy": policy_path} if policy_path else {})
    if config.thresholds is None:
        raise ElicitError("scoring needs thresholds: the config holds none")
    common = {
        "config": config_dict(config),
        "inputs": inputs,
        **scores_fields(config.thresholds),
        "obs_dim": pf.schema_arrow.field("obs").type.list_size,
        "action_dim": action_dim,
        "task": header.get("task", "unknown"),
        "policy_kind": str(policy.kind),
        "policy": {**dict(policy_info or {}), POLICY_KEY: policy_sha256(policy)},
        **scale_note(policy, config),
    }
    n_total = pf.metadata.num_rows
    scores_header = make_header(SCORES_KIND, SCHEMA_VERSION, **common, n_pairs=n_total)
    schema = schema.with_metadata({HEADER_KEY: dumps(scores_header).encode()})
    batches = read_demo_batches(demos_path, config.chunk_size, (*_CORE, *passthrough))
    scored = score_batches(
        policy,
        batches,
        config,
        str(demos_path),
        n_total,
        policy_source=str(policy_path or "<policy>"),
        bounds=(header.get("action_low", -1.0), header.get("action_high", 1.0)),
    )
    ep_path = episodes_path(out_path)
    shown = progress(n_total) if progress is not None else contextlib.nullcontext(_no_op)
    # the scores and their episode summary are put in place together (all or none)
    with atomic_paths([ep_path, out_path]) as (ep_tmp, tmp), shown as advance:
        episodes = _write_scores(tmp, schema, scored, config.accept_fraction, advance)
        ep_header = make_header(
            EPISODES_KIND,
            SCHEMA_VERSION,
            **common,
            scores_file=out_path.name,
            n_episodes=len(episodes["episode"]),
        )
        write_parquet(ep_tmp, episodes_table(episodes), ep_header)
    return ScoreResult(out_path, ep_path, n_total, episodes)


def scale_note(policy: Policy, config: ScoreConfig) -> dict[str, Any]:
    """``--action-scale std``: the dims the base never moved and how they were scored, for
    the scores header (``still_action_dims``, ``action_scale_note``); else nothing."""
    from elicit_jax.compat.scorer import still_dims

    still = still_dims(policy) if config.action_scale == "std" else []
    if not still:
        return {}
    return {
        "still_action_dims": still,
        "action_scale_note": (
            f"action dim(s) {still} never moved in the base policy's training actions (std 0): "
            "scored in units of the median std of the other dims, so an operator who drives "
            "them is told apart from one who does not"
        ),
    }


def _open_demos(demos_path: Path, policy: Policy) -> tuple[dict[str, Any], Any]:
    """The header and Parquet file of a demonstrations artifact the policy can score: checked
    as every reader checks it (:func:`~elicit_jax.data.demos.check_demos_layout`: kind,
    schema version, core columns, episode layout), with fixed-size obs/action lists of the
    policy's dimensions (the values are checked per chunk as they are scored)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    header = check_demos_layout(demos_path)
    pf = pq.ParquetFile(demos_path)
    missing = [c for c in (*_CORE, "success") if c not in pf.schema_arrow.names]
    if missing:
        raise ElicitError(f"missing column(s) {', '.join(missing)}", demos_path)
    for name in ("obs", "action"):
        if not pa.types.is_fixed_size_list(pf.schema_arrow.field(name).type):
            raise ElicitError(f"column '{name}' must be a fixed-size list of float32", demos_path)
    obs_dim = pf.schema_arrow.field("obs").type.list_size
    action_dim = pf.schema_arrow.field("action").type.list_size
    spans = header.get("obs_fields") or {}
    fields = tuple(k for k, _ in sorted(spans.items(), key=lambda kv: kv[1][0]))
    check_dims(policy, obs_dim, action_dim, str(demos_path), fields)
    return header, pf


def _write_scores(
    tmp: Path,
    schema: Any,
    scored: Iterator[dict[str, np.ndarray]],
    accept_fraction: float,
    advance: Callable[[int], None],
) -> dict[str, np.ndarray]:
    """Write the scored batches to ``tmp`` in row groups of about :data:`ROW_GROUP` rows;
    the per-episode summary columns."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    acc = EpisodeAccumulator(accept_fraction)
    with pq.ParquetWriter(tmp, schema, compression="zstd") as writer:
        pending: list[Any] = []
        for out in scored:
            pending.append(_arrow_table(out, schema))
            if sum(t.num_rows for t in pending) >= ROW_GROUP:
                writer.write_table(pa.concat_tables(pending))
                pending = []
            acc.add(out)
            advance(len(out["episode"]))
        if pending:
            writer.write_table(pa.concat_tables(pending))
    return acc.columns()


def read_scores(
    path: str | Path, columns: Sequence[str] | None = None, optional: Sequence[str] = ()
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Header and columns (numpy; ``prediction`` as (N, A)) of a scores artifact.

    Args:
      path: the scores file.
      columns: columns to read (default all).
      optional: more columns to read when the file has them.
    """
    import pyarrow.parquet as pq

    header = read_artifact(path, SCORES_KIND, SCHEMA_VERSION, what="scores")
    if columns:
        have = pq.read_schema(path).names
        columns = [*columns, *(c for c in optional if c in have and c not in columns)]
    table = pq.read_table(path, columns=list(columns) if columns else None)
    out: dict[str, np.ndarray] = {}
    for name in table.column_names:
        col = table.column(name).combine_chunks()
        if name == "prediction":
            out[name] = col.flatten().to_numpy().astype(np.float32).reshape(len(col), -1)
        elif name == "operator":
            out[name] = np.asarray(col.to_pylist(), dtype=object)
        else:
            out[name] = col.to_numpy(zero_copy_only=False)
    for k in ("likelihood", "novelty"):
        if k in out and not np.isfinite(out[k]).all():
            raise ElicitError(f"column '{k}' holds non-finite values", path)
    return header, out


def one_member_note(policy: Policy, config: ScoreConfig) -> str | None:
    """The warning a one-member policy earns (``None`` otherwise): with a single member and no
    dropout samples, novelty is 0 everywhere (an MDN's likelihood still varies)."""
    if policy.n_members * max(config.dropout_samples, 1) == 1 and not policy.entry.own_spread:
        return (
            "the policy has one member: novelty is 0 for every state, so every state counts as "
            "familiar and M rests on the likelihood error alone"
        )
    return None
