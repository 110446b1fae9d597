"""Which simulated task a policy belongs to: the one its training data recorded.

Every simulated task has 23-value observations and 7-value actions, so a policy runs on any
of them without an error: a reach-pillar policy evaluated on square-nut scores 0% and says
nothing. The commands that take ``--task`` with a policy (``evaluate``, ``elicit``,
``serve``) therefore default to the task the policy's run records, and refuse another one
unless forced (:func:`resolve_task`).

A run records its training demonstrations' task: a simulated task's name for collected
demos, the environment's name (``NutAssemblySquare``) for imported ones, or ``unknown``. A
task accepts its own name, its preset aliases and its ``recorded_as`` names
(:class:`~elicit_jax.sim.registry.TaskEntry`). The recorded task is read from headers alone by
:func:`~elicit_jax.policy.loaded.recorded_task`, the reader
:attr:`~elicit_jax.policy.loaded.LoadedPolicy.task` comes from too (no policy is loaded here).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from elicit_jax.errors import ElicitError
from elicit_jax.policy.loaded import UNKNOWN_TASKS, recorded_task
from elicit_jax.sim.registry import TASKS

__all__ = ["check_same_task", "recorded_task", "resolve_task", "tasks_accepting"]


def tasks_accepting(recorded: str) -> list[str]:
    """The simulated tasks whose policies may record ``recorded`` as their task."""
    name = recorded.strip().lower()
    return [
        t.name
        for t in TASKS.values()
        if recorded == t.name or name in (*t.preset_aliases, *t.recorded_as)
    ]


def resolve_task(
    given: str | None, policies: Sequence[str | Path], force: bool = False
) -> tuple[str, list[str]]:
    """The task to run ``policies`` on, and notes to show.

    Args:
      given: ``--task`` (``None``: not given).
      policies: run or seed directories (and demos files: a session's base demos).
      force: run ``given`` even when a policy records another task.

    Returns:
      ``(task, notes)``: ``given``, or the one task every policy's record names; a note when
      forced past a mismatch.

    Raises:
      ElicitError: ``given`` is not the task a policy records (without ``force``); no task
        given and none recorded, several possible, or the policies disagree.
    """
    recorded = {str(p): recorded_task(p) for p in policies}
    known = {p: r for p, r in recorded.items() if r is not None}
    if given is not None:
        notes = []
        for path, task in known.items():
            if given in tasks_accepting(task):
                continue
            msg = (
                f"records task '{task}', not '{given}' (every task takes the same 23 "
                "observations and 7 actions, so it would run without an error and its "
                "success would mean nothing)"
            )
            if not force:
                raise ElicitError(
                    f"{msg}; drop --task to use the recorded task, or pass --force", path
                )
            notes.append(f"warning: {path} {msg}; --force: running on '{given}' anyway")
        return given, notes
    if not known:
        unnamed = ", ".join(recorded) or "the policy"
        raise ElicitError(f"{unnamed}: records no task (unknown); pass --task")
    options: set[str] | None = None
    for path, task in known.items():
        accepting = set(tasks_accepting(task))
        if not accepting:
            raise ElicitError(
                f"records task '{task}', which is not a simulated task (known: "
                f"{', '.join(TASKS)}); pass --task (with --force)",
                path,
            )
        options = accepting if options is None else options & accepting
    if not options:
        tasks = ", ".join(f"{p}: {t}" for p, t in known.items())
        raise ElicitError(f"the inputs record different tasks ({tasks}); pass --task")
    if len(options) > 1:
        path, task = next(iter(known.items()))
        raise ElicitError(
            f"records task '{task}', which any of {', '.join(sorted(options))} plays; pass --task",
            path,
        )
    return options.pop(), []


def check_same_task(data_task: str, policy: str | Path, source: str | Path) -> None:
    """Refuse demonstrations of one simulated task judged by a policy trained on another
    (``watch``); names that are no simulated task's (LeRobot instructions, ``unknown``)
    cannot be compared and pass.

    Args:
      data_task: the task the demonstrations record.
      policy: the policy's run or seed directory.
      source: the demonstrations' file, named in the error.

    Raises:
      ElicitError: both name simulated tasks, and no task plays both.
    """
    trained = recorded_task(policy)
    if trained is None or data_task.strip().lower() in UNKNOWN_TASKS:
        return
    ours, theirs = set(tasks_accepting(data_task)), set(tasks_accepting(trained))
    if ours and theirs and not ours & theirs:
        raise ElicitError(
            f"holds demonstrations of task '{data_task}', but the policy ({policy}) was "
            f"trained on '{trained}': its verdicts would mean nothing (--task names the "
            "demonstrations' task if the file's is wrong)",
            source,
        )
