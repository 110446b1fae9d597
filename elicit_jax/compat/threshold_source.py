"""The thresholds (λ, η) a command runs with, and where they came from.

Every command that takes thresholds (``score``, ``filter``, ``map``, ``elicit``, ``serve``,
``watch``) resolves them here, from exactly one of a thresholds file, an explicit pair, or a
paper preset, so each validates them the same way and can show the user how far to trust them.
"""

from __future__ import annotations

from pathlib import Path

from elicit_jax.compat.thresholds import STAND_IN, Thresholds, check_units, read_thresholds
from elicit_jax.errors import ElicitError


def resolve_thresholds(
    file: Path | None,
    lam: float | None,
    eta: float | None,
    preset: str | None = None,
    action_scale: str | None = None,
) -> Thresholds | None:
    """Thresholds from exactly one of a thresholds file, ``lam``/``eta``, or a preset.

    Args:
      file: a thresholds.json written by ``fit-thresholds``.
      lam: λ given by hand (goes with ``eta``).
      eta: η given by hand (goes with ``lam``).
      preset: the name of a paper preset (``square-nut``, ...).
      action_scale: the action scale of the scores they will be compared with (``none``:
        raw action units; ``std``: per-dim scaled), or None not to check units. A file must
        have been fitted on scores of that scale; a preset (raw units) does not apply to
        ``std`` scores.

    Returns:
      The thresholds, or None when none of the three is given.

    Raises:
      ElicitError: more than one source, λ without η (or the reverse), an unknown preset,
        an unreadable file, λ or η not finite and > 0, or thresholds in the wrong units.
    """
    given = [file is not None, lam is not None or eta is not None, preset is not None]
    if sum(given) > 1:
        raise ElicitError("give only one of --thresholds, --lambda/--eta, --preset")
    if (lam is None) != (eta is None):
        raise ElicitError("--lambda and --eta go together")
    if file is not None:
        read = read_thresholds(file)
        if action_scale is not None:
            check_units(read, action_scale)
        return read
    if lam is not None and eta is not None:
        return Thresholds(lam, eta, "given", action_scale=action_scale or "none")
    if preset is not None:
        from elicit_jax.compat.measures import PRESETS

        if preset not in PRESETS:
            raise ElicitError(f"unknown preset '{preset}' (choose {', '.join(sorted(PRESETS))})")
        if action_scale == "std":
            raise ElicitError(
                f"--action-scale std: --preset {preset} is in raw action units and does not "
                "apply to std-scaled scores; give --lambda/--eta in std-scaled units, "
                "--thresholds fitted on std-scaled scores, or no thresholds (docs/thresholds.md)"
            )
        return Thresholds(*PRESETS[preset], f"preset {preset}")
    return None


def task_thresholds(task: str, action_scale: str = "none") -> tuple[Thresholds, list[str]]:
    """The thresholds to score with when none are given, and what to tell the user.

    The paper preset of ``task``; a task without one borrows square-nut's values (a warning
    says so, and the source records it). Scores in ``std`` units get the preset too, recorded
    as a raw-unit preset whose M and accept/reject are not verdicts: the presets are in raw
    action units.

    Args:
      task: the demonstrations' task.
      action_scale: the scale of the scores (``none`` or ``std``).

    Returns:
      The thresholds (their ``source`` says which and why) and the lines for stderr.
    """
    from elicit_jax.compat.measures import PRESETS, preset_for_task

    name = preset_for_task(task)
    if name is not None:
        lam, eta = PRESETS[name]
        source = f"preset {name} (task {task})"
        note = f"thresholds: paper preset {name} (λ={lam}, η={eta}) for task {task}"
    else:
        lam, eta = PRESETS["square-nut"]
        source = f"borrowed: square-nut preset, not fitted for task {task} (it has no preset)"
        note = (
            f"warning: task '{task}' has no paper preset; M and accept/reject use square-nut's "
            f"λ={lam}, η={eta}, borrowed, not fitted for it. Fit your own "
            "(elicit-jax fit-thresholds) and pass --thresholds to filter and map."
        )
    if action_scale != "std":
        return Thresholds(lam, eta, source), [note]
    note = (
        "warning: --action-scale std: the paper presets are in raw action units, so M and "
        "accept/reject in this file are not verdicts; ℓ and ν are std-scaled. "
        "Fit thresholds on these scores (elicit-jax fit-thresholds) and pass --thresholds to "
        "filter and map."
    )
    source = f"{STAND_IN}, not valid for --action-scale std scores: {source}"
    return Thresholds(lam, eta, source, action_scale="std", stand_in=True), [note]
