"""Options shared by the commands that run elicitation sessions (``elicit``, ``serve``).

Each is declared once here, so both commands spell, document and validate a setting the
same way; unset options are ``None`` and fall back to :class:`SessionConfig`'s defaults.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from elicit_jax.cli.app import check_seed
from elicit_jax.cli.threshold_options import PRESET  # noqa: F401  (serve spells it so.PRESET)

if TYPE_CHECKING:
    from elicit_jax.compat.thresholds import Thresholds

TASK = typer.Option(
    None,
    "--task",
    help="Simulated task (see `elicit-jax tasks`; default: the one the policy records).",
)
POLICY = typer.Option(None, "--policy", help="Base policy (run or seed directory).")
BASE_DEMOS = typer.Option(None, "--base-demos", help="D_base (demos artifact).")
FORCE_TASK = typer.Option(
    False,
    "--force",
    help="Run --task although the policy or D_base records another task, or with thresholds "
    "fitted for another policy.",
)


def _flag(name: str, kind: type, text: str, **extra: Any) -> tuple[str, type, Any]:
    """``(name, kind, option)`` of a session flag: ``--name`` (``--name/--no-name`` for a
    bool), ``None`` when not given."""
    flag = "--" + name.replace("_", "-")
    decl = f"{flag}/--no-{flag[2:]}" if kind is bool else flag
    return name, kind, typer.Option(None, decl, help=text, **extra)


SESSION_FLAGS = (
    _flag("mode", str, "informed (default) or naive (control)."),
    _flag("show", str, "Informed mode: parts shown, comma-separated [prompt,indicator,feedback]."),
    _flag("demos", int, "Demonstrations wanted [10]."),
    _flag("batch", int, "Retrain after every N accepted [0: never]."),
    _flag("fixed_base", bool, "Score every batch against π_base."),
    _flag("dagger", bool, "HG-DAgger: robot acts."),
    _flag("practice", int, "Practice episodes first [3]."),
    _flag("prompt", int, "Base demos shown in the prompt [5]."),
    _flag("accept_fraction", float, "Reject above this fraction incompatible [0.05]."),
    _flag("reject_count", int, "Reject above N incompatible pairs (original code's rule)."),
    _flag("window", int, "Feedback window length [10]."),
    _flag("windows", int, "Feedback windows on a rejection [3]."),
    _flag("retrieval", str, "l2 (paper, default) or dtw."),
    _flag("likelihood", str, "ensemble-mean (paper, default) or member-average."),
    _flag("ddof", int, "Novelty std convention: 0 paper, 1 code."),
    _flag("which", str, "Checkpoint: best (default), final, epoch."),
    _flag("policy_seed", int, "Seed of a multi-seed run."),
    _flag("seed", int, "Session seed (initial states) [0].", callback=check_seed),
    _flag("max_episodes", int, "Stop after N episodes [practice + 5 x demos]."),
    _flag("horizon", int, "Steps per episode [the task's]."),
)
"""The protocol's settings as (parameter name, type, option), in ``--help`` order: a command
adds them with :func:`elicit_jax.cli.params.with_flags` and reads them with :func:`given`."""

SERVE_FLAGS = tuple(f for f in SESSION_FLAGS if f[0] != "show")
"""``serve``'s: every session flag but ``--show`` (the interface ablation of ``elicit``)."""

THRESHOLD_FIELDS = ("thresholds",)
"""SessionConfig fields the thresholds flags resolve (through ``thresholds_from_flags``)."""


def given(params: dict[str, Any]) -> dict[str, Any]:
    """The session settings among a command's ``params`` that were set (``None``: not
    given), paths as strings; thresholds are resolved separately."""
    from elicit_jax.elicit.config import SessionConfig

    fields = {f.name for f in dataclasses.fields(SessionConfig)} - set(THRESHOLD_FIELDS)
    out = {k: v for k, v in params.items() if k in fields and v is not None}
    for k in ("policy", "base_demos"):
        if k in out:
            out[k] = str(out[k])
    if isinstance(out.get("show"), str):
        out["show"] = tuple(p.strip() for p in out["show"].split(",") if p.strip())
    return out


def recorded_task(given: dict[str, Any], force: bool) -> None:
    """Set ``given['task']`` to the task the policy and D_base record when ``--task`` is not
    given, and refuse another one without ``--force`` (printing what was chosen or forced);
    nothing to check without a policy."""
    from elicit_jax.sim.task_match import resolve_task

    inputs = [given[k] for k in ("policy", "base_demos") if k in given]
    if "policy" not in given:
        return
    task, notes = resolve_task(given.get("task"), inputs, force)
    if "task" not in given:
        notes.insert(0, f"task: {task} (recorded by {given['policy']})")
    for note in notes:
        typer.echo(note, err=True)
    given["task"] = task


def thresholds_fit_policy(
    thresholds: Thresholds | None,
    policy: str | Path,
    which: str | int,
    seed: int | None,
    force: bool,
) -> None:
    """Refuse thresholds fitted for another policy than the session's (``--force`` turns the
    refusal into a warning), as ``score``, ``filter`` and ``map`` do; prints any warning.

    Raises:
      ElicitError: the thresholds file names another policy and ``force`` is false.
    """
    from elicit_jax.compat.threshold_source import check_policy
    from elicit_jax.policy.loaded import load_policy

    if thresholds is None or thresholds.file is None:
        return
    # a file that does not record its policy cannot be checked (a warning says so)
    own = None if thresholds.policy is None else load_policy(policy, which, seed=seed).sha256
    warning = check_policy(thresholds, own, str(policy), force)
    if warning:
        typer.echo(warning, err=True)
