"""Scripted operators per task: a registry of named styles (see :mod:`.base`)."""

from __future__ import annotations

import importlib
from typing import Any

from elicit_jax.errors import ElicitError
from elicit_jax.sim.env import Task
from elicit_jax.sim.operators.base import Operator, Style

_MODULES = {
    "reach-pillar": "reach_pillar",
    "square-nut": "square_nut",
    "round-nut": "round_nut",
    "hammer-drawer": "hammer_drawer",
    "robosuite-square": "robosuite_nuts",
    "robosuite-round": "robosuite_nuts",
}


def _module(task_name: str) -> Any:
    if task_name not in _MODULES:
        raise ElicitError(f"no scripted operators for task '{task_name}'")
    try:
        return importlib.import_module(f"elicit_jax.sim.operators.{_MODULES[task_name]}")
    except ModuleNotFoundError as e:
        raise ElicitError(f"no scripted operators for task '{task_name}'") from e


def operator_names(task_name: str) -> dict[str, str]:
    """Operator name -> one-line description, for a task."""
    return {k: d for k, (_, d) in _module(task_name).STYLES.items()}


def style_names(task_name: str) -> list[str]:
    """Names of a task's scripted styles, in registry order (their styles are not read)."""
    return list(_module(task_name).STYLES)


def style_of(task_name: str, name: str) -> Style:
    """The :class:`Style` registered as ``name`` for a task.

    Raises:
      ElicitError: unknown style for this task.
    """
    styles = _module(task_name).STYLES
    if name not in styles:
        raise ElicitError(
            f"task '{task_name}' has no operator '{name}' (known: {', '.join(styles)})"
        )
    return styles[name][0]


def make_operator(task: Task, name: str, style: Style | None = None) -> Operator:
    """The scripted operator ``name`` of ``task`` (its registered style unless ``style``).

    Raises:
      ElicitError: unknown operator for this task.
    """
    mod = _module(task.name)
    if name not in mod.STYLES and style is None:
        known = ", ".join(mod.STYLES)
        raise ElicitError(f"task '{task.name}' has no operator '{name}' (known: {known})")
    return mod.OPERATOR_CLASS(task, style or mod.STYLES[name][0], name)


__all__ = ["Operator", "Style", "make_operator", "operator_names", "style_names", "style_of"]
