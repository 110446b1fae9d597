"""``elicit-jax info SESSION``: phase, counts, accept rate and per-demonstration verdicts;
``elicit-jax info FOLDER``: one row per operator session of a ``serve`` folder."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def describe_session(path: Path, header: dict[str, Any]) -> None:
    """Print a session's settings, progress and the verdict of each demonstration."""
    from rich.console import Console
    from rich.table import Table

    from elicit_jax.elicit.config import SessionConfig
    from elicit_jax.elicit.progress import Progress, session_phase
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
        ("thresholds", f"λ = {config.thresholds.lam:.4g}, η = {config.thresholds.eta:.4g}"),
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


def describe_sessions_folder(path: Path) -> None:
    """Print one row per operator session under ``path`` and the totals."""
    from rich.console import Console
    from rich.table import Table

    from elicit_jax.elicit.sessions_folder import session_dirs, session_summary
    from elicit_jax.errors import ElicitError

    console = Console(highlight=False)
    table = Table(title=f"{path}: sessions of several operators", title_justify="left")
    cols = ("operator", "task", "mode", "phase", "episodes", "accepted", "rejected", "failed")
    for col in (*cols, "last verdict"):
        table.add_column(col, justify="right" if col in cols[4:] else "left")
    total, operators, broken = 0, 0, []
    for d in session_dirs(path):
        try:
            s = session_summary(d)
        except ElicitError as e:
            broken.append(str(e))
            continue
        c = s["counts"]
        operators += 1
        total += c.accepted
        table.add_row(
            s["name"], s["task"], s["mode"], s["phase"], str(c.episodes),
            f"{c.accepted}/{c.wanted}", str(c.rejected), str(c.failed), s["last_verdict"] or "-",
        )  # fmt: skip
    console.print(table)
    console.print(f"{operators} operator(s), {total} accepted demonstration(s) in all")
    for line in broken:
        console.print(f"[red]unreadable session[/]: {line}")
    removed = path / ".removed"
    if removed.is_dir() and session_dirs(removed):
        console.print(f"removed from the study (not counted): {len(session_dirs(removed))}")
