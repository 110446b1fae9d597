"""``elicit-jax info SESSION``: phase, counts, accept rate and per-demonstration verdicts."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def session_phase(config: Any, progress: Any) -> str:
    """Where a (possibly interrupted) session stands."""
    c = progress.counts
    if c.accepted >= config.demos:
        return "done (all demonstrations accepted)"
    if c.episodes >= config.episode_limit:
        return f"done (episode limit {config.episode_limit} reached)"
    if c.practice < config.practice:
        return f"practice ({c.practice} of {config.practice} done)"
    return "demonstrate"


def describe_session(path: Path, header: dict[str, Any]) -> None:
    """Print a session's settings, progress and the verdict of each demonstration."""
    from rich.console import Console
    from rich.table import Table

    from elicit_jax.elicit.config import SessionConfig
    from elicit_jax.elicit.progress import Progress
    from elicit_jax.elicit.store import SessionStore

    config = SessionConfig.from_dict(header["config"])
    progress = Progress.load(SessionStore(path), config)
    c = progress.counts
    judged = c.accepted + c.rejected
    console = Console(highlight=False)
    top = Table(title=f"{path}: elicitation session", show_header=False, title_justify="left")
    top.add_column(style="bold")
    top.add_column(overflow="fold")
    rows = [
        ("phase", session_phase(config, progress)),
        ("task / operator", f"{config.task} / {config.operator}"),
        ("mode", config.mode + (" + HG-DAgger" if config.dagger else "")),
        ("thresholds", f"λ = {config.lambda_:.4g}, η = {config.eta:.4g}"),
        ("rule", config.rule().describe()),
        ("episodes", f"{c.episodes} ({c.practice} practice)"),
        ("accepted", f"{c.accepted} of {config.demos} wanted"),
        ("rejected / failed", f"{c.rejected} / {c.failed}"),
        ("accept rate", f"{c.accepted / judged:.0%} of judged" if judged else "-"),
        ("created", header.get("created")),
    ]
    for k, v in rows:
        top.add_row(k, str(v))
    console.print(top)
    table = Table("episode", "kind", "verdict", "length", "incompatible", "interventions", "batch")
    for r in progress.rows:
        frac = r["fraction_incompatible"]
        rate = r["intervention_rate"]
        table.add_row(
            str(r["index"]),
            str(r["episode_kind"]),
            str(r["verdict"]),
            str(r["length"]),
            "-" if frac is None else f"{100 * frac:.1f}%",
            "-" if rate is None else f"{r['interventions']} ({100 * rate:.0f}% of steps)",
            str(r["batch"]),
        )
    console.print(table)
