"""What a person would do: imagination with its own calm controller.

:func:`imagine` answers "what would I do at each of these states?": it runs a noise-free copy
of the person's operator (its own speed and gain, its own parameters θ; no motor noise, no
hesitation, no jitter) along a sequence of states someone else visited, feeding each state in
turn (teacher forcing), so the operator's phases advance as the states say.
:func:`action_error` compares the imagined actions with the ones shown. Parameters that match
the demonstrator's way predict the shown actions closely; a wrist turned the other way predicts
the opposite turn, and phases stall where the states never meet the person's own waypoints.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from elicit_jax.sim.operators import Style, make_operator

Choices = Mapping[str, Any]


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
