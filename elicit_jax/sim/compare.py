"""Paired comparison of success outcomes on the same initial states (exact McNemar test).

Two backends (or two policies) rolled out from the same seeded initial states give paired
pass/fail outcomes. Pairs where both agree carry no information about a difference in success
rate; under the null hypothesis of equal rates each discordant pair (one succeeded, the other
failed) is equally likely to go either way, so the count of one kind among the ``d``
discordant pairs is Binomial(d, 1/2). The exact two-sided p-value is
``min(1, 2 * P[X <= min(b, c)])`` with ``b``, ``c`` the two discordant counts.

Example:
    >>> r = mcnemar_exact([1, 1, 1, 0], [1, 0, 0, 0])
    >>> (r.only_a, r.only_b, r.p_value)
    (2, 0, 0.5)
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.policy.base import Policy


@dataclasses.dataclass(frozen=True)
class PairedSuccess:
    """Result of an exact McNemar test on paired success outcomes.

    Attributes:
      n: number of pairs (initial states).
      both: pairs where both succeeded.
      only_a: pairs where only ``a`` succeeded.
      only_b: pairs where only ``b`` succeeded.
      neither: pairs where both failed.
      p_value: exact two-sided p-value of equal success rates.
    """

    n: int
    both: int
    only_a: int
    only_b: int
    neither: int
    p_value: float

    @property
    def rate_a(self) -> float:
        """Success rate of ``a``."""
        return (self.both + self.only_a) / self.n

    @property
    def rate_b(self) -> float:
        """Success rate of ``b``."""
        return (self.both + self.only_b) / self.n

    def consistent(self, alpha: float = 0.01) -> bool:
        """Whether equal success rates are not rejected at level ``alpha``."""
        return self.p_value > alpha


def mcnemar_exact(a: Any, b: Any) -> PairedSuccess:
    """Exact McNemar test of ``a (N,)`` against ``b (N,)``, boolean outcomes on the same N
    initial states.

    Raises:
      ElicitError: empty or differently sized outcome vectors, or non-0/1 values.
    """
    a, b = np.asarray(a), np.asarray(b)
    if a.ndim != 1 or a.shape != b.shape or len(a) == 0:
        raise ElicitError(
            f"paired outcomes need two equally long, non-empty vectors; got {a.shape} and {b.shape}"
        )
    for name, x in (("a", a), ("b", b)):
        if not np.isin(x, (0, 1)).all():
            raise ElicitError(f"outcomes {name} must be booleans (0/1)")
    a, b = a.astype(bool), b.astype(bool)
    only_a, only_b = int(np.sum(a & ~b)), int(np.sum(~a & b))
    d, k = only_a + only_b, min(only_a, only_b)
    tail = sum(math.comb(d, i) for i in range(k + 1)) / 2**d
    return PairedSuccess(
        n=len(a),
        both=int(np.sum(a & b)),
        only_a=only_a,
        only_b=only_b,
        neither=int(np.sum(~a & ~b)),
        p_value=min(1.0, 2.0 * tail),
    )


def compare_backends(
    task: Any, policy: Policy, seeds: np.ndarray, horizon: int | None = None, threads: int = 0
) -> tuple[PairedSuccess, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Roll ``policy`` out on MJX (``a``) and on C MuJoCo (``b``) from the same ``seeds (N,)``.

    Returns:
      ``(test, mjx_out, mujoco_out)``: the McNemar test of the two success vectors and each
      backend's per-rollout outputs.
    """
    from elicit_jax.sim.evaluate import rollout_mujoco_policy
    from elicit_jax.sim.rollout_mjx import rollout_mjx

    h = int(horizon or task.config.horizon)
    m = rollout_mjx(task, policy, seeds, h)
    c = rollout_mujoco_policy(task, policy, np.asarray(seeds), h, threads)
    return mcnemar_exact(m["success"], c["success"]), m, c
