"""Options shared by the commands that run elicitation sessions (``elicit``, ``serve``).

Each is declared once here, so both commands spell, document and validate a setting the
same way; unset options are ``None`` and fall back to :class:`SessionConfig`'s defaults.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import typer

from elicit_jax.cli.app import check_seed
from elicit_jax.cli.threshold_options import PRESET  # noqa: F401  (serve spells it so.PRESET)

TASK = typer.Option(None, "--task", help="Simulated task (see `elicit-jax tasks`).")
POLICY = typer.Option(None, "--policy", help="Base policy (run or seed directory).")
BASE_DEMOS = typer.Option(None, "--base-demos", help="D_base (demos artifact).")
MODE = typer.Option(None, "--mode", help="informed (default) or naive (control).")
SHOW = typer.Option(
    None, "--show", help="Informed mode: parts shown, comma-separated [prompt,indicator,feedback]."
)
DEMOS = typer.Option(None, "--demos", help="Demonstrations wanted [10].")
BATCH = typer.Option(None, "--batch", help="Retrain after every N accepted [0: never].")
FIXED_BASE = typer.Option(
    None, "--fixed-base/--no-fixed-base", help="Score every batch against π_base."
)
DAGGER = typer.Option(None, "--dagger/--no-dagger", help="HG-DAgger: robot acts.")
PRACTICE = typer.Option(None, "--practice", help="Practice episodes first [3].")
PROMPT = typer.Option(None, "--prompt", help="Base demos shown in the prompt [5].")
ACCEPT_FRACTION = typer.Option(
    None, "--accept-fraction", help="Reject above this fraction incompatible [0.05]."
)
REJECT_COUNT = typer.Option(
    None, "--reject-count", help="Reject above N incompatible pairs (original code's rule)."
)
WINDOW = typer.Option(None, "--window", help="Feedback window length [10].")
WINDOWS = typer.Option(None, "--windows", help="Feedback windows on a rejection [3].")
RETRIEVAL = typer.Option(None, "--retrieval", help="l2 (paper, default) or dtw.")
LIKELIHOOD = typer.Option(
    None, "--likelihood", help="ensemble-mean (paper, default) or member-average."
)
DDOF = typer.Option(None, "--ddof", help="Novelty std convention: 0 paper, 1 code.")
WHICH = typer.Option(None, "--which", help="Checkpoint: best (default), final, epoch.")
POLICY_SEED = typer.Option(None, "--policy-seed", help="Seed of a multi-seed run.")
SEED = typer.Option(None, "--seed", help="Session seed (initial states) [0].", callback=check_seed)
MAX_EPISODES = typer.Option(
    None, "--max-episodes", help="Stop after N episodes [practice + 5 x demos]."
)
HORIZON = typer.Option(None, "--horizon", help="Steps per episode [the task's].")


SESSION_FLAGS = (
    ("mode", str, MODE),
    ("show", str, SHOW),
    ("demos", int, DEMOS),
    ("batch", int, BATCH),
    ("fixed_base", bool, FIXED_BASE),
    ("dagger", bool, DAGGER),
    ("practice", int, PRACTICE),
    ("prompt", int, PROMPT),
    ("accept_fraction", float, ACCEPT_FRACTION),
    ("reject_count", int, REJECT_COUNT),
    ("window", int, WINDOW),
    ("windows", int, WINDOWS),
    ("retrieval", str, RETRIEVAL),
    ("likelihood", str, LIKELIHOOD),
    ("ddof", int, DDOF),
    ("which", str, WHICH),
    ("policy_seed", int, POLICY_SEED),
    ("seed", int, SEED),
    ("max_episodes", int, MAX_EPISODES),
    ("horizon", int, HORIZON),
)
"""The protocol's settings as (parameter name, type, option), in ``--help`` order: a command
adds them with :func:`elicit_jax.cli.params.with_flags` and reads them with :func:`given`."""

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
