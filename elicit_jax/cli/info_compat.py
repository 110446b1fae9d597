"""``elicit-jax info`` for compatibility artifacts: scores, episode scores, thresholds, logs."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np


def _kv(title: str, rows: list[tuple[str, Any]]) -> None:
    from rich.console import Console

    from elicit_jax.cli.info_demos import kv_table

    Console().print(kv_table(title, rows))


def _inputs(header: dict[str, Any]) -> list[tuple[str, Any]]:
    return [
        (f"input {k}", f"{v.get('path')} (sha256 {str(v.get('sha256'))[:12]}…)")
        for k, v in header.get("inputs", {}).items()
    ]


def describe_scores(path: Path, header: dict[str, Any]) -> None:
    """Thresholds, config, dims and inputs, then the per-operator table of its episodes."""
    from elicit_jax.compat.score import episodes_path

    cfg = header.get("config", {})
    _kv(
        f"{path}: per-pair compatibility scores (schema v{header.get('schema_version')})",
        [
            ("pairs", header.get("n_pairs")),
            ("task", header.get("task")),
            ("dims (obs, action)", (header.get("obs_dim"), header.get("action_dim"))),
            ("policy kind", header.get("policy_kind")),
            ("thresholds", header.get("thresholds")),
            ("thresholds from", header.get("thresholds_source")),
            (
                "action scale / dropout samples",
                f"{cfg.get('action_scale', 'none')} / {cfg.get('dropout_samples', 0)}",
            ),
            ("likelihood / ddof", f"{cfg.get('likelihood')} / {cfg.get('ddof')}"),
            ("accept fraction", cfg.get("accept_fraction")),
            *_inputs(header),
        ],
    )
    ep = episodes_path(path)
    if ep.exists():
        describe_episode_scores(ep, None)


def describe_episode_scores(path: Path, header: dict[str, Any] | None) -> None:
    """Per-operator summary of the per-episode scores."""
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    cols = {
        n: (
            np.asarray(table.column(n).to_pylist(), dtype=object)
            if n == "operator"
            else table.column(n).to_numpy()
        )
        for n in table.column_names
    }
    print_operator_table(cols, title=f"{path.name}: episodes per operator")


def describe_thresholds(path: Path, header: dict[str, Any]) -> None:
    """The thresholds, how they were obtained, and their report."""
    from rich.console import Console

    from elicit_jax.compat.show import print_report
    from elicit_jax.compat.thresholds import ETA_KEY, LAMBDA_KEY, POLICY_KEY

    _kv(
        f"{path}: thresholds ({header.get('method')})",
        [
            ("lambda", header.get(LAMBDA_KEY)),
            ("eta", header.get(ETA_KEY)),
            ("fitted for policy", header.get(POLICY_KEY) or "not recorded"),
            ("compatible set", header.get("config", {}).get("compatible")),
            ("incompatible set", header.get("config", {}).get("incompatible")),
            *_inputs(header),
        ],
    )
    if "report" in header and "per_operator" in header["report"]:
        print_report(header, Console())


def describe_filter_log(path: Path, header: dict[str, Any]) -> None:
    """Dropped pairs per operator and reason."""
    import pyarrow.parquet as pq

    table = pq.read_table(path, columns=["operator", "episode", "reason"])
    ops = np.asarray(table.column("operator").to_pylist(), dtype=object).astype(str)
    eps = table.column("episode").to_numpy()
    rows = [("config", header.get("config")), ("dropped pairs", header.get("n_dropped"))]
    for op in sorted(set(ops.tolist())):
        sel = ops == op
        rows.append((f"operator {op}", f"{int(sel.sum())} pairs in {len(set(eps[sel]))} episodes"))
    reasons = sorted(set(table.column("reason").to_pylist()))
    rows += [("reason", r) for r in reasons] + _inputs(header)
    _kv(f"{path}: filter log", rows)


def print_operator_table(episodes: Mapping[str, np.ndarray], title: str = "scores") -> None:
    """Rich table per operator: episodes, pairs, % incompatible, mean M, accepted/rejected."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title)
    for col in (
        "operator",
        "episodes",
        "pairs",
        "incompatible %",
        "mean M",
        "accepted",
        "rejected",
    ):
        table.add_column(col, justify="left" if col == "operator" else "right")
    ops = np.asarray(episodes["operator"]).astype(str)
    for op in sorted(set(ops.tolist())):
        sel = ops == op
        n = int(episodes["length"][sel].sum())
        inc = int(episodes["n_incompatible"][sel].sum())
        mean_m = float((episodes["mean_compatibility"][sel] * episodes["length"][sel]).sum() / n)
        acc = int(episodes["accepted"][sel].sum())
        table.add_row(
            op,
            str(int(sel.sum())),
            str(n),
            f"{100 * inc / n:.1f}",
            f"{mean_m:.3f}",
            str(acc),
            str(int(sel.sum()) - acc),
        )
    Console().print(table)
