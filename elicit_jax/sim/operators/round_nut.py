"""Scripted operators of ``round-nut``: the square nut's styles (same phases and choices)."""

from __future__ import annotations

from elicit_jax.sim.operators.square_nut import STYLES, SquareNutOperator

OPERATOR_CLASS = SquareNutOperator
__all__ = ["OPERATOR_CLASS", "STYLES"]
