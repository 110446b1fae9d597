"""``elicit-jax elicit`` on the console: open or resume the session, run it with a console
reporter (one line per episode, the feedback of each rejection), and print a summary table."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from elicit_jax.elicit.config import SessionConfig
from elicit_jax.elicit.events import EpisodeEndEvent, Event, RetrainEvent, ReviewEvent
from elicit_jax.elicit.run import run_session
from elicit_jax.elicit.session import Session


class ConsoleReporter:
    """Prints one line per finished episode and the feedback of informed rejections."""

    def __init__(self, session: Session, console: Any = None) -> None:
        from rich.console import Console

        self.console = console or Console(highlight=False)
        self.session = session

    def __call__(self, event: Event) -> None:
        if isinstance(event, EpisodeEndEvent):
            row = self.session.progress.rows[-1]
            c = event.counts
            verdict = str(row.get("verdict", "")).upper()
            self.console.print(
                f"e{event.episode:04d} {event.episode_kind:<13} {verdict:<9} "
                f"[{c.accepted}/{c.wanted} accepted, {c.episodes} episodes] {row.get('text', '')}",
                soft_wrap=True,
            )
        elif isinstance(event, ReviewEvent) and event.verdict == "rejected":
            for fb in event.feedback:
                self.console.print(f"      feedback: {fb.text}", soft_wrap=True)
        elif isinstance(event, RetrainEvent):
            what = "training" if event.status == "start" else "trained"
            self.console.print(
                f"batch {event.batch}: {what} π_new on D_base + {event.demos} demos -> "
                f"{event.policy}"
            )


def summary_table(session: Session) -> Any:
    """A rich table of the session's counts and rates."""
    from rich.table import Table

    c = session.progress.counts
    demos = [r for r in session.progress.rows if r["episode_kind"] == "demonstration"]
    judged = [r for r in demos if r["verdict"] in ("accepted", "rejected")]
    fracs = [r["fraction_incompatible"] for r in demos if r["fraction_incompatible"] is not None]
    rates = [r["intervention_rate"] for r in demos if r["intervention_rate"] is not None]
    table = Table(title=f"session {session.setup.store.root}", title_justify="left")
    table.add_column("what")
    table.add_column("value", justify="right")
    rows = [
        ("ended", session.end_reason or "stopped"),
        ("mode", session.config.mode + (" + HG-DAgger" if session.config.dagger else "")),
        ("practice episodes", c.practice),
        ("demonstrations accepted", f"{c.accepted} of {c.wanted} wanted"),
        ("rejected by the rule", c.rejected),
        ("failed the task", c.failed),
        ("accept rate (of judged)", f"{c.accepted / len(judged):.0%}" if judged else "-"),
        ("mean fraction incompatible", f"{sum(fracs) / len(fracs):.1%}" if fracs else "-"),
        ("mean intervention rate", f"{sum(rates) / len(rates):.0%}" if rates else "-"),
        (
            "policy scoring last",
            f"batch {session.setup.policy_batch}" if session.setup.policy_batch else "base",
        ),
    ]
    for k, v in rows:
        table.add_row(k, str(v))
    return table


def elicit(
    config: SessionConfig,
    out: str | Path,
    *,
    overwrite: bool = False,
    resume: bool = False,
    quiet: bool = False,
) -> Session:
    """Open (or resume) the session in ``out`` and run it with its configured operator.

    Returns:
      The finished session.
    """
    from rich.console import Console

    from elicit_jax.elicit.setup import open_session

    console = Console(highlight=False, quiet=quiet)
    setup, operator, resumed = open_session(
        config, out, overwrite=overwrite, resume=resume, quiet=quiet
    )
    if resumed:
        console.print(f"resuming the session in {out}")
    # which (λ, η) the session judges by, and where they came from
    console.print(f"thresholds: {setup.config.thresholds.describe()}", markup=False)
    session = run_session(setup, operator, [lambda s: ConsoleReporter(s, console)])
    console.print(summary_table(session))
    return session
