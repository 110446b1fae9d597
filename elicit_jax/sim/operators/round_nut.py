"""Scripted operators of ``round-nut``: the square nut's styles (same phases and choices).

The round nut has the square nut's handle, so the same state machine and styles apply: see
:mod:`elicit_jax.sim.operators.square_nut` for what each style does and where the
conflicting ones (``conflict-flip-pause`` above all) differ from the base
(``benchmarks/results/phenomenon-round-nut.md`` measures them on this task).
"""

from __future__ import annotations

from elicit_jax.sim.operators.square_nut import DEFAULT_CHOICES, STYLES, SquareNutOperator

OPERATOR_CLASS = SquareNutOperator
__all__ = ["DEFAULT_CHOICES", "OPERATOR_CLASS", "STYLES"]
