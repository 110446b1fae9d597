"""The thresholds (λ, η) a command runs with, where they came from, and whether they apply.

Every command that takes thresholds (``score``, ``filter``, ``map``, ``elicit``, ``serve``,
``watch``) resolves them here, from exactly one of a thresholds file, an explicit pair, or a
paper preset, so each validates them the same way and can show the user how far to trust them;
the commands that apply them to scores check here that they fit those scores: the same units
(:func:`check_units`), the same policy (:func:`check_policy`), and not a stand-in
(:func:`applied_thresholds`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from elicit_jax.compat.thresholds import (
    STAND_IN,
    Thresholds,
    read_thresholds,
    scores_policy,
    scores_thresholds,
)
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


def check_units(t: Thresholds, action_scale: str) -> None:
    """Raise unless ``t`` is in the units of scores of ``action_scale`` (``none``: raw action
    units; ``std``: per-dim scaled). λ and η of one scale mean nothing on the other, and no
    exact conversion exists."""
    if t.action_scale != action_scale:
        raise ElicitError(
            f"these thresholds were fitted on --action-scale {t.action_scale} scores and do "
            f"not apply to --action-scale {action_scale} scores: fit thresholds on scores of "
            "the same scale (docs/thresholds.md)",
            t.file,
        )


def check_policy(t: Thresholds, policy: str | None, what: str, force: bool = False) -> str | None:
    """Refuse thresholds fitted for another policy than the one ``what`` comes from.

    Args:
      t: the thresholds (from a file: they record their policy).
      policy: the content hash of the policy of ``what`` (None: not recorded).
      what: the scores file or checkpoint they are applied to (named in the message).
      force: apply them anyway (the refusal becomes a warning).

    Returns:
      A warning line, or None when the policies match or ``t`` is not from a file.

    Raises:
      ElicitError: the two policies differ and ``force`` is false.
    """
    if t.file is None:
        return None
    if t.policy is None or policy is None:
        which = t.file if t.policy is None else what
        return (
            f"warning: {which} does not record its policy (written by an older elicit-jax): "
            f"cannot check that {t.file} was fitted for the policy of {what}"
        )
    if t.policy == policy:
        return None
    message = (
        f"{t.file} was fitted for another policy (params {t.policy[:12]}) than {what} "
        f"(params {policy[:12]}); refit on scores of that policy, or --force"
    )
    if force:
        return f"warning: {message} given: applied anyway"
    raise ElicitError(message)


def applied_thresholds(
    header: Mapping[str, Any],
    scores_path: str | Path,
    given: Thresholds | None,
    force: bool = False,
) -> tuple[Thresholds, list[str]]:
    """The thresholds a command applies to a scores file, and the lines to tell the user.

    ``given`` (from ``--thresholds``, ``--lambda``/``--eta``) must have been fitted for the
    policy the scores came from (:func:`check_policy`); without them, the values the scores
    file was judged under are used, and said so — unless those are a raw-unit preset standing
    in on std-scaled scores (not a verdict), which is refused.

    Args:
      header: the scores file's header.
      scores_path: the scores file (named in messages).
      given: thresholds from the command line, or None.
      force: apply them anyway: another policy's thresholds, or a stand-in preset.

    Returns:
      The thresholds, and the lines for stderr (which λ, η and where from; warnings).

    Raises:
      ElicitError: another policy's thresholds or stand-in values, without ``force``.
    """
    if given is not None:
        warning = check_policy(given, scores_policy(header), str(scores_path), force)
        return given, [f"thresholds: {given.describe()}", *([warning] if warning else [])]
    stored = scores_thresholds(header, scores_path)
    lines = [
        f"thresholds: {stored.describe()}; pass --thresholds to apply a fitted thresholds.json"
    ]
    if stored.stand_in:
        message = (
            f"{scores_path} was scored with --action-scale std: its λ, η are a raw-unit preset "
            "standing in, not a verdict; give --thresholds fitted on these scores (or "
            "--lambda/--eta in std-scaled units), or --force"
        )
        if not force:
            raise ElicitError(message)
        lines.append(f"warning: {message} given: applied anyway")
    return stored, lines
