"""``elicit-jax serve``: the browser interface for elicitation sessions."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from elicit_jax.cli import session_options as so
from elicit_jax.cli import threshold_options as th
from elicit_jax.cli.app import ELICIT, app
from elicit_jax.cli.params import with_flags
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.compat.thresholds import Thresholds
    from elicit_jax.web.hub import OperatorHub

DEMO_TASK = "reach-pillar"


@app.command("serve", rich_help_panel=ELICIT)
@with_flags((*so.SERVE_FLAGS, *th.FLAGS_AND_PRESET))
def serve_cmd(
    ctx: typer.Context,
    sessions: Path = typer.Option(
        Path("sessions"), "--sessions", help="Sessions directory (one folder per operator)."
    ),
    demo: bool = typer.Option(
        False,
        "--demo",
        help="Built-in reach-pillar base policy, demos and thresholds (built once, cached).",
    ),
    demo_dir: Path = typer.Option(
        None, "--demo-dir", help="Where --demo keeps its inputs [~/.cache/elicit-jax/serve-demo]."
    ),
    host: str = typer.Option("127.0.0.1", "--host", help="Address to bind (others need a token)."),
    port: int = typer.Option(8765, "--port", help="Port (0: any free one)."),
    token: str = typer.Option(
        None, "--token", help="Access token (made up off loopback when not given)."
    ),
    admin_token: str = typer.Option(
        None, "--admin-token", help="Token of the /admin dashboard (made up when not given)."
    ),
    allow_host: list[str] = typer.Option(
        [], "--allow-host", help="Another name operators use to reach the server (repeatable)."
    ),
    max_operators: int = typer.Option(16, "--max-operators", help="Most operators at once."),
    task: str = so.TASK,
    policy: Path = so.POLICY,
    base_demos: Path = so.BASE_DEMOS,
    force: bool = so.FORCE_TASK,
    **flags: Any,
) -> None:
    """Serve elicitation sessions in the browser: each operator opens the printed URL, enters
    a name and goes through practice, prompt, demonstrations with the live indicator, and
    feedback; accepted demonstrations land in SESSIONS/<name>/ (a restart resumes them).
    The experimenter watches and manages operators at the printed /admin URL.

    Example: elicit-jax serve --task square-nut --policy runs/base --base-demos base.parquet
    --thresholds thresholds.json --sessions sessions/

    Example: elicit-jax serve --demo   (reach-pillar, nothing else needed)

    robosuite tasks (robosuite-square, robosuite-round) need the robosuite extra; each
    operator's environment runs in the server's process.
    """
    from elicit_jax.web.serve import serve

    given = so.given(ctx.params)
    chosen = th.from_params(ctx.params, action_scale="none")
    if demo_dir is not None and not demo:
        raise ElicitError("--demo-dir goes with --demo")
    if demo:
        chosen = _demo_inputs(given, demo_dir, policy, base_demos, chosen)
    else:
        so.recorded_task(given, force)
    server = {"sessions": str(sessions), "host": host, "port": port, "token": token}
    server |= {"max_operators": max_operators, "admin_token": admin_token}
    config = _serve_config(given, chosen, allow_hosts=tuple(allow_host), **server)
    th.show_chosen(config.session.thresholds)
    s = config.session
    so.thresholds_fit_policy(s.thresholds, s.policy, s.which, s.policy_seed, force)
    serve(config, echo=typer.echo, summary=_print_summary)


def _serve_config(given: dict[str, Any], chosen: Thresholds | None, **server: Any) -> Any:
    """The ``ServeConfig`` of the given flags (``server``: its fields other than the session)
    and the thresholds, kept whole (their source, file and recorded verdict).

    Raises:
      ElicitError: an input or the thresholds missing.
    """
    from elicit_jax.elicit.config import SessionConfig
    from elicit_jax.web.serve import ServeConfig, with_person_horizon

    missing = [
        f"--{k.replace('_', '-')}" for k in ("task", "policy", "base_demos") if k not in given
    ]
    if chosen is None:
        missing.append("thresholds (--thresholds, --lambda/--eta or --preset)")
    if missing:
        raise ElicitError(f"missing {', '.join(missing)} (or use --demo)")
    session = SessionConfig.from_dict({**given, "operator": "browser:_"}, thresholds=chosen)
    # a person at a keyboard needs longer than the task's horizon, unless told otherwise
    return ServeConfig(
        session=session if "horizon" in given else with_person_horizon(session), **server
    )


def _demo_inputs(
    given: dict[str, Any],
    demo_dir: Path | None,
    policy: Path | None,
    base_demos: Path | None,
    chosen: Thresholds | None,
) -> Thresholds | None:
    """``--demo``: the built-in inputs (built once, cached) go into ``given``; returns the
    thresholds read from the built-in thresholds file.

    Raises:
      ElicitError: an input flag or another task given with ``--demo``.
    """
    from rich.console import Console

    from elicit_jax.pipeline.serve_demo import DemoRecipe, demo_inputs

    clash = [
        flag
        for flag, value in (("--policy", policy), ("--base-demos", base_demos))
        if value is not None
    ] + (["thresholds"] if chosen is not None else [])
    if clash:
        raise ElicitError(f"--demo brings its own inputs; drop {', '.join(clash)}")
    if given.get("task", DEMO_TASK) != DEMO_TASK:
        raise ElicitError(f"--demo serves {DEMO_TASK}; drop --task or choose {DEMO_TASK}")
    inputs = demo_inputs(DemoRecipe(task=DEMO_TASK), demo_dir, echo=typer.echo, console=Console())
    given |= {"task": DEMO_TASK, "policy": str(inputs.policy)}
    given["base_demos"] = str(inputs.base_demos)
    return th.thresholds_from_flags(inputs.thresholds, None, None)


def _print_summary(hub: OperatorHub) -> None:
    """The table of operators served, once the server stopped."""
    from rich.console import Console

    Console(highlight=False).print(summary_table(hub))


def summary_table(hub: OperatorHub) -> Any:
    """Per operator served: state, counts."""
    from rich.table import Table

    table = Table(title=f"operators served ({hub.root})", title_justify="left")
    for col in ("operator", "state", "accepted", "rejected", "failed", "episodes", "steps"):
        table.add_column(col, justify="left" if col in ("operator", "state") else "right")
    for name, d in sorted(hub.drivers.items()):
        c = d.session.progress.counts if d.session is not None else None
        cells = (
            ["-"] * 4
            if c is None
            else [f"{c.accepted}/{c.wanted}", c.rejected, c.failed, c.episodes]
        )
        table.add_row(name, d.state, *[str(v) for v in cells], str(d.steps))
    return table
