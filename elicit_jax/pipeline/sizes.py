"""Named study sizes: how many demonstrations D_base and each D_new hold, apart from the
training profile.

A filtering definition's tasks give their own counts (``base_episodes``, ``new_episodes``):
those are the ``default`` sizes. A task may name other sizes in ``[task.sizes.<name>]``
tables, each with its own ``base_episodes`` and ``new_episodes``; a run chooses one or several
sizes (``[pipeline] sizes``, or ``pipeline run --sizes``), all validated here by
:func:`choose_sizes`. Several sizes in one run are planned side by side
(:func:`sized_specs`): the default sizes keep the stage ids of a run without sizes, every other
sizes ``<name>`` puts ``sizes-<name>/`` into its stages' ids and outputs and records
``sizes = "<name>"`` in their configs, so one run folder holds both and the report sets them
side by side. The same collection seeds serve every sizes, so a smaller D_base starts from the
initial states of the larger one's first attempts.

The paper's proportions (Gandhi et al., CoRL 2022): Square Nut 50 base + 50 per operator,
Round Nut 30 base + 10 per operator (its "paper" sizes in ``pipelines/robosuite.toml``).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping, Sequence
from typing import Any

from elicit_jax.errors import ElicitError

DEFAULT_SIZES = "default"
"""The sizes every task has: its own ``base_episodes`` and ``new_episodes``."""
SIZES_KEYS = frozenset({"base_episodes", "new_episodes"})
"""The keys of a ``[task.sizes.<name>]`` table."""
SIZES_PREFIX = "sizes-"
"""Stage ids and outputs of the sizes ``<name>`` have ``sizes-<name>/`` after their first part."""
_NAME = re.compile(r"^[a-z0-9][a-z0-9_-]*$")


def task_sizes(raw: Any, task: str, source: str) -> tuple[tuple[str, int, int], ...]:
    """A task's named sizes from its ``sizes`` table, as ``(name, base, new)`` triples.

    Raises:
      ElicitError: not a table, a bad name (``default`` is the task's own counts), an unknown
        key, or a count that is not an integer ≥ 1.
    """
    if raw is None:
        return ()
    if not isinstance(raw, Mapping):
        raise ElicitError(f"[[task]] {task}: sizes must be a table of [task.sizes.<name>]", source)
    out = []
    for name, table in raw.items():
        where = f"[task.sizes.{name}] of {task}"
        if name == DEFAULT_SIZES or not _NAME.match(str(name)):
            raise ElicitError(
                f"{where}: sizes are named in lower case (a-z, 0-9, -, _) and not "
                f"'{DEFAULT_SIZES}' (the task's own counts)",
                source,
            )
        if not isinstance(table, Mapping) or set(table) != SIZES_KEYS:
            raise ElicitError(f"{where} must set exactly base_episodes and new_episodes", source)
        counts = [table["base_episodes"], table["new_episodes"]]
        if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in counts):
            raise ElicitError(f"{where}: counts must be integers ≥ 1, got {counts}", source)
        out.append((str(name), int(counts[0]), int(counts[1])))
    return tuple(out)


def sizes_names(value: Any, source: str) -> tuple[str, ...]:
    """The sizes a run asks for: a name, a comma-separated list of names (``--sizes``), or a
    list (``[pipeline] sizes``); default :data:`DEFAULT_SIZES`.

    Raises:
      ElicitError: empty, not names, or a name given twice.
    """
    if value is None:
        return (DEFAULT_SIZES,)
    items = value.split(",") if isinstance(value, str) else value
    if not isinstance(items, list | tuple) or not all(isinstance(s, str) for s in items):
        raise ElicitError(f"sizes must be a name or a list of names, got {value!r}", source)
    names = tuple(s.strip() for s in items if s.strip())
    if not names:
        raise ElicitError("sizes must name at least one sizes (e.g. default)", source)
    if len(set(names)) != len(names):
        raise ElicitError(f"sizes are listed twice: {', '.join(names)}", source)
    return names


def choose_sizes(value: Any, tasks: Sequence[Any], source: str) -> tuple[str, ...]:
    """The sizes a run asks for (:func:`sizes_names`), each defined for every task.

    Args:
      value: ``[pipeline] sizes`` or the ``--sizes`` flag (``None``: the default sizes).
      tasks: the definition's tasks (each with ``name`` and ``sizes`` triples).
      source: the definition file, for the error.

    Raises:
      ElicitError: one line naming the file, the sizes unknown and the sizes defined.
    """
    names = sizes_names(value, source)
    defined = dict.fromkeys([DEFAULT_SIZES, *(s[0] for t in tasks for s in t.sizes)])
    for name in names:
        if name not in defined:
            raise ElicitError(
                f"unknown sizes '{name}' (this definition defines: {', '.join(defined)})", source
            )
        missing = [t.name for t in tasks if name != DEFAULT_SIZES and name not in dict_of(t)]
        if missing:
            raise ElicitError(
                f"sizes '{name}' is not defined for task {', '.join(missing)} (add "
                f"[task.sizes.{name}] with base_episodes and new_episodes)",
                source,
            )
    return names


def dict_of(task: Any) -> dict[str, tuple[int, int]]:
    """A task's named sizes as ``name -> (base, new)``, the default sizes included."""
    own = {DEFAULT_SIZES: (task.base_episodes, task.new_episodes)}
    return own | {name: (base, new) for name, base, new in task.sizes}


def resized(task: Any, name: str) -> Any:
    """``task`` with the counts of its sizes ``name``."""
    base, new = dict_of(task)[name]
    return dataclasses.replace(task, base_episodes=base, new_episodes=new)


def sized_specs(spec: Any) -> list[tuple[str, Any]]:
    """Each sizes of a run and the spec its stages are planned from: the tasks at that sizes.

    A task whose counts at a sizes equal its default counts is planned once, under
    ``default``, when the run has the default sizes too (the same demos and policies: the
    report shows them for both); a sizes left with no task is dropped.
    """
    out = []
    for name in spec.sizes:
        tasks = tuple(
            resized(t, name)
            for t in spec.tasks
            if name == DEFAULT_SIZES
            or DEFAULT_SIZES not in spec.sizes
            or dict_of(t)[name] != dict_of(t)[DEFAULT_SIZES]
        )
        if tasks:
            out.append((name, dataclasses.replace(spec, tasks=tasks)))
    return out


def in_sizes(stage: Any, name: str, side_by_side: bool) -> Any:
    """``stage`` moved into the sizes ``name``: ``sizes-<name>/`` after the first part of its
    id, output and input ids (a kind whose outputs sit side by side, ``side_by_side``, a map:
    ``maps/sizes-<name>-<file>``)."""
    if name == DEFAULT_SIZES:
        return stage
    return stage.moved(f"{SIZES_PREFIX}{name}", side_by_side, f"{name} sizes")


def sized_task(task: str, name: str) -> str:
    """How reports name a task at the sizes ``name`` (the task itself at the default sizes),
    so every table keeps the sizes of a run apart."""
    return task if name == DEFAULT_SIZES else f"{task} ({name} sizes)"


def unsized_task(label: str, name: str) -> str:
    """The task of a report label :func:`sized_task` made."""
    suffix = f" ({name} sizes)"
    return label[: -len(suffix)] if name != DEFAULT_SIZES and label.endswith(suffix) else label


def report_sizes(configs: Mapping[str, Any]) -> dict[str, dict[str, tuple[int, int]]]:
    """The sizes a run reported, in order, with each task's ``(D_base, D_new)`` counts, from
    its report stage's config (empty: the default sizes only, as every run before sizes)."""
    for cfg in configs.get("report", {}).values():
        raw = cfg.get("sizes") or {}
        return {n: {t: (int(c[0]), int(c[1])) for t, c in ts.items()} for n, ts in raw.items()}
    return {}


def sizes_line(sizes: Sequence[str], counts: Mapping[str, Mapping[str, tuple[int, int]]]) -> str:
    """The report's statement of the sizes a run used: per sizes, each task's D_base and D_new
    counts (``counts``: sizes -> task -> (base, new), from the collect stages)."""
    parts = []
    for name in sizes:
        tasks = counts.get(name, {})
        each = "; ".join(f"{t} {b} + {n} per operator" for t, (b, n) in tasks.items())
        parts.append(f"**{name}** ({each or 'no collection finished'})")
    return (
        "Study sizes (D_base + D_new demonstrations per operator; the training profile is the "
        "same for every sizes): " + ", ".join(parts) + "."
    )
