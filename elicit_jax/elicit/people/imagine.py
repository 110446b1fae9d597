"""A person's knowledge of the task: the ways each step can be done, and "what would I do here".

**Repertoire.** A style's *choices* (grasp point, wrist turn, approach, carry order, pauses,
...) are what a person can change; its motor parameters (speed, gain) are not. The repertoire
of a task holds, for every choice key, the operator's default (:data:`UNSET`) and every value
some scripted style of the task uses — except the base operator's style, which is never
read: a person knows the ways people do the task, not which one the base operator took.

**Imagination.** :func:`imagine` answers "what would I do at each of these states?": it runs
a noise-free copy of the person's operator (no motor noise, no hesitation, no jitter) along a
sequence of states someone else visited, feeding each state in turn (teacher forcing), so the
operator's phases advance as the states say. :func:`action_error` compares the imagined
actions with the ones shown. A style whose choices match the demonstrator's predicts the shown
actions closely; a style that, say, turns the wrist the other way predicts the opposite turn,
and its phases stall where the states never meet its own waypoints.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from elicit_jax.sim.operators import Style, make_operator, style_names, style_of

UNSET = "<default>"
"""A choice left to the operator's default."""
BASE_STYLE = "base"
"""The base operator's registry name: its style is never read."""

Choices = Mapping[str, Any]


def same_value(a: Any, b: Any) -> bool:
    """Equality of choice values (numbers within 1e-9, tuples element-wise)."""
    if isinstance(a, int | float) and isinstance(b, int | float):
        return abs(float(a) - float(b)) < 1e-9
    if isinstance(a, tuple | list) and isinstance(b, tuple | list):
        return len(a) == len(b) and all(same_value(x, y) for x, y in zip(a, b, strict=True))
    return type(a) is type(b) and a == b


def repertoire(task_name: str, styles: Sequence[str] | None = None) -> dict[str, list[Any]]:
    """Choice key -> the values a person knows for it (:data:`UNSET` first).

    Args:
      task_name: the task.
      styles: styles whose choices make up the repertoire (default: every registered style of
        the task but the base operator's). Naming ``base`` is refused.
    """
    from elicit_jax.errors import ElicitError

    names = list(styles) if styles is not None else style_names(task_name)
    if styles is not None and BASE_STYLE in names:
        raise ElicitError("a person's repertoire cannot be read from the base operator's style")
    out: dict[str, list[Any]] = {}
    for name in names:
        if name == BASE_STYLE:
            continue
        for key, value in style_of(task_name, name).choices:
            values = out.setdefault(key, [UNSET])
            if not any(same_value(value, v) for v in values):
                values.append(value)
    return out


def with_choice(choices: Choices, key: str, value: Any) -> dict[str, Any]:
    """``choices`` with ``key`` set to ``value`` (removed for :data:`UNSET`)."""
    out = dict(choices)
    if isinstance(value, str) and value == UNSET:
        out.pop(key, None)
    else:
        out[key] = value
    return out


def alternatives(choices: Choices, known: Mapping[str, Sequence[Any]]) -> Iterator[tuple]:
    """Every single-choice change ``(key, value, new_choices)`` the repertoire allows."""
    for key, values in known.items():
        current = choices.get(key, UNSET)
        for value in values:
            if not same_value(value, current):
                yield key, value, with_choice(choices, key, value)


def pairs(choices: Choices, known: Mapping[str, Sequence[Any]]) -> Iterator[tuple]:
    """Every change of two different choices at once ``(changes, new_choices)``."""
    singles = list(alternatives(choices, known))
    for i, (k1, v1, _) in enumerate(singles):
        for k2, v2, _ in singles[i + 1 :]:
            if k2 != k1:
                yield ((k1, v1), (k2, v2)), with_choice(with_choice(choices, k1, v1), k2, v2)


def calm(style: Style, choices: Choices) -> Style:
    """``style`` with ``choices`` and without motor noise, hesitation or jitter."""
    return dataclasses.replace(
        style, choices=tuple(choices.items()), noise=0.0, hesitate_prob=0.0, jitter=0.0
    )


def imagine(task: Any, style: Style, segments: Sequence[np.ndarray]) -> list[np.ndarray]:
    """What ``style`` would do at each state of each segment, fed the states in order.

    Args:
      task: the simulated task.
      style: the (calm) style to imagine with.
      segments: state sequences ``(T_i, O)``; each starts the operator afresh.

    Returns:
      Imagined actions ``(T_i, A)`` per segment.
    """
    if not segments:
        return []
    lengths = [len(s) for s in segments]
    horizon = max(lengths)
    obs = np.stack([_pad(np.asarray(s, np.float64), horizon) for s in segments])
    op = make_operator(task, "imagined", style=style)
    op.reset(obs[:, 0], np.random.default_rng(0))
    out = np.zeros((len(segments), horizon, 7))
    for t in range(horizon):
        out[:, t] = op.act(obs[:, t])
    return [out[i, :n] for i, n in enumerate(lengths)]


def _pad(states: np.ndarray, horizon: int) -> np.ndarray:
    if len(states) == horizon:
        return states
    return np.concatenate([states, np.repeat(states[-1:], horizon - len(states), 0)])


def action_error(
    imagined: Sequence[np.ndarray],
    shown: Sequence[np.ndarray],
    spans: Sequence[slice] | None = None,
    weights: np.ndarray | None = None,
) -> float:
    """Mean squared difference of imagined and shown actions over ``spans`` of each segment.

    Args:
      imagined, shown: per segment ``(T_i, A)``.
      spans: the steps compared per segment (default: all).
      weights: (A,) per-dimension weights (default: equal).
    """
    total, count = 0.0, 0
    for i, (a, b) in enumerate(zip(imagined, shown, strict=True)):
        span = spans[i] if spans is not None else slice(None)
        d = (np.asarray(a)[span] - np.asarray(b, np.float64)[span]) ** 2
        if weights is not None:
            d = d * weights / weights.mean()
        total += float(d.sum())
        count += d.size
    return total / max(count, 1)
