"""Accept/reject rules for one demonstration, from its incompatible pairs.

* ``fraction`` (the paper, default): reject when the incompatible pairs exceed
  ``fraction × length`` (5%) — :func:`elicit_jax.compat.measures.rejects`;
* ``count`` (the original code's ``--sample_threshold``): reject when they exceed an
  absolute number ``N`` (``--reject-count N``), whatever the length.

A demonstration that does not complete the task is never accepted, whatever its scores.
"""

from __future__ import annotations

import dataclasses

from elicit_jax.compat.measures import check_accept_fraction, rejects
from elicit_jax.errors import ElicitError


@dataclasses.dataclass(frozen=True)
class AcceptRule:
    """How a demonstration is judged.

    Attributes:
      fraction: reject above this fraction of incompatible pairs (used when ``count`` is None).
      count: reject above this many incompatible pairs (the original code's rule), or None.
    """

    fraction: float = 0.05
    count: int | None = None

    def __post_init__(self) -> None:
        check_accept_fraction(self.fraction)
        if self.count is not None and self.count < 0:
            raise ElicitError(f"--reject-count must be >= 0, got {self.count}")

    @property
    def kind(self) -> str:
        return "fraction" if self.count is None else "count"

    def allowed(self, length: int) -> float:
        """Most incompatible pairs a demonstration of ``length`` scored steps may hold."""
        return float(self.count) if self.count is not None else self.fraction * length

    def rejects(self, n_incompatible: int, length: int) -> bool:
        """True when a demonstration with these counts is rejected."""
        if self.count is not None:
            return n_incompatible > self.count
        return rejects(n_incompatible, length, self.fraction)

    def describe(self) -> str:
        """The rule in words."""
        if self.count is not None:
            return f"reject when more than {self.count} pairs are incompatible"
        return f"reject when more than {100 * self.fraction:g}% of pairs are incompatible"
