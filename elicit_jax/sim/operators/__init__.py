"""Scripted operators per task: named styles (see :mod:`.base`), found through the task's
registry entry (:attr:`elicit_jax.sim.registry.TaskEntry.operators`)."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError
from elicit_jax.sim.env import Task
from elicit_jax.sim.operators.base import NO_PAUSE, Operator, Style
from elicit_jax.sim.registry import TASKS


def _module(task_name: str) -> Any:
    if task_name not in TASKS:
        raise ElicitError(f"no scripted operators for task '{task_name}'")
    return importlib.import_module(f"elicit_jax.sim.operators.{TASKS[task_name].operators}")


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


def episode_traits(task_name: str) -> Callable[[np.ndarray, np.ndarray], Any] | None:
    """The task's per-episode trait measure ``measure(obs (T, O), action (T, A))``, whose
    result has a ``conflicts`` property (what the episode did, measured from its own states;
    e.g. :func:`elicit_jax.sim.operators.nut_traits.measure`), or None when the task measures
    none. The operators module names it ``MEASURE_TRAITS``.
    """
    return getattr(_module(task_name), "MEASURE_TRAITS", None)


def full_choices(task_name: str, name: str) -> dict[str, Any]:
    """Every choice the style ``name`` acts with: its own, and the operator class's
    ``DEFAULT_CHOICES`` (the base operator's) for those it does not set. For measuring a
    simulated person's distance from a style; a person never reads it.

    Raises:
      ElicitError: unknown style for this task.
    """
    style = style_of(task_name, name)
    defaults = getattr(_module(task_name), "DEFAULT_CHOICES", {})
    return {**NO_PAUSE, **defaults, **dict(style.choices)}


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


__all__ = [
    "Operator", "Style", "episode_traits", "full_choices", "make_operator", "operator_names",
    "style_names", "style_of",
]  # fmt: skip
