"""``elicit-jax info`` for evaluation artifacts (kind ``rollouts``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def describe_rollouts(path: Path, header: dict[str, Any]) -> None:
    """Print an evaluation's settings and its summary table."""
    import pandas as pd
    from rich.console import Console

    from elicit_jax.cli.sim_cmds import print_summary

    console = Console()
    cfg = header.get("config", {})
    console.print(
        f"[bold]{path}[/]: rollouts (schema v{header.get('schema_version', '?')}), task "
        f"{header.get('task', '?')}, backend {header.get('backend', '?')}, "
        f"{cfg.get('rollouts', '?')} rollouts per policy from initial-state seed "
        f"{cfg.get('seed', '?')}, select {cfg.get('select', '?')}, {header.get('n_rows', '?')} rows"
    )
    print_summary(console, pd.DataFrame(header.get("summary", [])))
