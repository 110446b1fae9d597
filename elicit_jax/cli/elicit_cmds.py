"""Elicitation commands: ``elicit`` (a live session) and ``watch`` (demonstrations in a folder)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from elicit_jax.cli import data_options as do
from elicit_jax.cli import session_options as so
from elicit_jax.cli import threshold_options as th
from elicit_jax.cli.app import ELICIT, app
from elicit_jax.cli.params import from_params, with_flags
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.elicit.watch import WatchConfig


def _stored_config(out: Path) -> dict[str, Any]:
    from elicit_jax.elicit.store import SessionStore

    if not (out / "artifact.json").is_file():
        raise ElicitError("holds no session to resume", out)
    return dict(SessionStore(out).header().get("config", {}))


@app.command("elicit", rich_help_panel=ELICIT)
@with_flags(so.SESSION_FLAGS, before="resume")
@with_flags(th.FLAGS_AND_PRESET, before="operator")
def elicit_cmd(
    ctx: typer.Context,
    out: Path = typer.Option(..., "-o", "--out", help="Session directory (created or resumed)."),
    task: str = so.TASK,
    policy: Path = so.POLICY,
    base_demos: Path = so.BASE_DEMOS,
    operator: str = typer.Option(
        None,
        "--operator",
        help="Who demonstrates: scripted:STYLE (a task's scripted operator) or "
        "person:STYLE[,trait=value,...] (a simulated person, docs/people.md).",
    ),
    resume: bool = typer.Option(
        False, "--resume", help="Continue the session in OUT with its recorded settings."
    ),
    overwrite: bool = typer.Option(False, "--overwrite", help="Start the session in OUT again."),
    force: bool = so.FORCE_TASK,
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress output."),
    **flags: Any,
) -> None:
    """Run an elicitation session: practice, prompt, demonstrations with live M, feedback.

    Re-running the same command resumes the session where it stopped (kill -9 loses at most
    the episode in progress); `--resume -o OUT` does so with the recorded settings.

    Example: elicit-jax elicit --task square-nut --policy runs/base --base-demos base.parquet
    --thresholds thresholds.json --operator scripted:conflict-flip-pause --mode informed
    --demos 10 --batch 5 -o sessions/op4
    """
    from elicit_jax.cli.session_console import elicit
    from elicit_jax.elicit.config import SessionConfig

    given = so.given(ctx.params)
    # live scoring is in raw action units (docs/thresholds.md)
    chosen = th.from_params(ctx.params, action_scale="none")
    if resume:
        config_dict = {**_stored_config(out), **given}
    else:
        so.recorded_task(given, force)
        missing = [
            f"--{k.replace('_', '-')}"
            for k in ("task", "policy", "base_demos", "operator")
            if k not in given
        ]
        if chosen is None:
            missing.append("thresholds (--thresholds, --lambda/--eta or --preset)")
        if missing:
            raise ElicitError(f"missing {', '.join(missing)} (or --resume an existing session)")
        config_dict = given
    config = SessionConfig.from_dict(config_dict, thresholds=chosen)
    so.thresholds_fit_policy(
        config.thresholds, config.policy, config.which, config.policy_seed, force
    )
    elicit(config, out, overwrite=overwrite, resume=resume, quiet=quiet)


@app.command("watch", rich_help_panel=ELICIT)
@with_flags(do.IMPORT_FLAGS)
@with_flags(th.FLAGS_AND_PRESET, before="out")
def watch_cmd(
    ctx: typer.Context,
    inbox: Path = typer.Argument(..., help="Folder where demonstrations land."),
    policy: Path = typer.Option(..., "--policy", help="Policy to score against."),
    base_demos: Path = typer.Option(..., "--base-demos", help="D_base (for feedback)."),
    out: Path = typer.Option(None, "-o", "--out", help="Pages and log [INBOX/verdicts]."),
    accept_fraction: float = typer.Option(0.05, "--accept-fraction", help="The 5% rule."),
    reject_count: int = typer.Option(None, "--reject-count", help="Reject above N pairs."),
    window: int = typer.Option(10, "--window", help="Feedback window length."),
    windows: int = typer.Option(3, "--windows", help="Feedback windows per demonstration."),
    retrieval: str = typer.Option("l2", "--retrieval", help="l2 (paper) or dtw."),
    likelihood: str = typer.Option("ensemble-mean", "--likelihood", help="Or member-average."),
    ddof: int = typer.Option(0, "--ddof", help="Novelty std convention: 0 paper, 1 code."),
    which: str = typer.Option("best", "--which", help="Checkpoint: best, final or an epoch."),
    policy_seed: int = typer.Option(None, "--policy-seed", help="Seed of a multi-seed run."),
    settle: float = typer.Option(2.0, "--settle", help="Seconds unchanged before reading."),
    poll: float = typer.Option(1.0, "--poll", help="Seconds between scans."),
    once: bool = typer.Option(False, "--once", help="Stop when everything present is judged."),
    timeout: float = typer.Option(None, "--timeout", help="Stop after this many seconds."),
    force: bool = typer.Option(
        False, "--force", help="Apply thresholds fitted for another policy (with a warning)."
    ),
    **flags: Any,
) -> None:
    """Give a verdict and feedback for each demonstration that lands in INBOX.

    Robomimic .hdf5 files and LeRobot dataset folders are read with `import`'s options once
    they stop changing (--settle); each demonstration gets a console line and an HTML/PNG
    page in OUT. Runs until interrupted (or --once / --timeout).

    Example: elicit-jax watch INBOX/ --policy runs/base --base-demos base.parquet
    --thresholds t.json
    """
    from elicit_jax.elicit.watch import Watcher

    config = _watch_config(ctx.params)
    so.thresholds_fit_policy(
        config.thresholds, config.policy, config.which, config.policy_seed, force
    )
    watcher = Watcher(config, echo=typer.echo)
    typer.echo(f"watching {inbox} (pages and log in {watcher.out}; Ctrl-C stops)")
    n = watcher.run()
    typer.echo(f"judged {n} demonstrations")


def _watch_config(params: dict[str, Any]) -> WatchConfig:
    """``watch``'s flags as a WatchConfig: thresholds resolved (in raw action units: live
    scoring is, docs/thresholds.md), the import flags checked as ``import`` checks them."""
    import dataclasses

    from elicit_jax.elicit.watch import WatchConfig

    p = params
    chosen = th.from_params(p, action_scale="none")
    if chosen is None:
        raise ElicitError("missing thresholds: give --thresholds, --lambda/--eta or --preset")
    th.show_chosen(chosen)
    imp = do.import_config(p["inbox"], "", p)
    options = tuple(
        (f.name, getattr(imp, f.name))
        for f in dataclasses.fields(imp)
        if f.name not in ("source", "out")
    )
    paths = {
        k: None if p[k] is None else str(p[k]) for k in ("inbox", "policy", "base_demos", "out")
    }
    return from_params(WatchConfig, p, **paths, thresholds=chosen, import_options=options)
