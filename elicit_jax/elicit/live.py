"""Live compatibility at control rate: ONE compiled single-state scorer per session.

:class:`LiveScorer` jits, once, a function of ``(policy, obs (O,), action (A,), λ, η)`` that
runs the ensemble on one state and applies the per-pair scorer
:func:`elicit_jax.compat.measures.score_pair` — the same definitions ``elicit-jax score``
uses. The policy and the thresholds are arguments, not constants, so a retrained policy of
the same architecture (π_new between batches), a new episode or new thresholds reuse the
compiled function: nothing recompiles during a session (:attr:`LiveScorer.traces` counts
the traces, and stays 1). Everything comes back in one small host transfer.

Only feed-forward policies (``mlp``, ``mdn``) can be scored one state at a time; an LSTM's
score depends on the whole history and is refused with a clear error.

Example:
    >>> scorer = LiveScorer(ScoreConfig(lambda_=0.4, eta=0.05))
    >>> s = scorer.score(policy, obs, action)     # StepScore(likelihood, novelty, ...)
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from elicit_jax.compat.measures import ScoreConfig, score_pair
from elicit_jax.errors import ElicitError


@dataclasses.dataclass(frozen=True)
class StepScore:
    """Scores of one state-action pair, plus the policy's own action at the state.

    Attributes:
      likelihood: ℓ.
      novelty: ν.
      compatibility: M in [0, 1].
      incompatible: M == 0.
      policy_action: (A,) the ensemble-mean action π̄(s), clipped to [-1, 1].
    """

    likelihood: float
    novelty: float
    compatibility: float
    incompatible: bool
    policy_action: np.ndarray


def check_live_policy(policy: Any, source: str = "<policy>") -> None:
    """Raise unless ``policy`` can be scored one state at a time (feed-forward)."""
    kind = getattr(policy, "kind", "mlp")
    if kind == "lstm":
        raise ElicitError(
            "live scoring needs a feed-forward policy (mlp or mdn); this one is an lstm, whose "
            "scores depend on the whole episode (score its demonstrations with `score`)",
            source,
        )


class LiveScorer:
    """One compiled single-state scorer (see the module docstring).

    Attributes:
      config: the score config (likelihood kind, ddof, clip; its thresholds are defaults).
      traces: times the scoring function was traced (1 after the first call, if nothing
        recompiled).
    """

    def __init__(self, config: ScoreConfig) -> None:
        import jax

        self.config = config
        self.traces = 0

        def one(policy: Any, obs: Any, action: Any, lam: Any, eta: Any) -> Any:
            import jax.numpy as jnp

            self.traces += 1
            members = policy.members(obs[None])[:, 0]  # (K, A)
            spread = policy.spread(obs[None])
            spread = None if spread is None else spread[0]
            s = score_pair(members, action, lam, eta, config, spread=spread)
            head = jnp.stack(
                [s.likelihood, s.novelty, s.compatibility, s.incompatible.astype(jnp.float32)]
            )
            return jnp.concatenate([head.astype(jnp.float32), s.mean.astype(jnp.float32)])

        self._fn = jax.jit(one)

    def score(
        self,
        policy: Any,
        obs: np.ndarray,
        action: np.ndarray,
        lambda_: float | None = None,
        eta: float | None = None,
    ) -> StepScore:
        """Score ``action (A,)`` at state ``obs (O,)`` under ``policy``.

        Args:
          policy: a feed-forward :class:`~elicit_jax.policy.base.Policy`.
          obs: (O,) state.
          action: (A,) action (for the policy's action alone, pass zeros and read
            ``policy_action``).
          lambda_: λ (default the config's).
          eta: η (default the config's).
        """
        lam = np.float32(self.config.lambda_ if lambda_ is None else lambda_)
        et = np.float32(self.config.eta if eta is None else eta)
        out = np.asarray(
            self._fn(policy, np.asarray(obs, np.float32), np.asarray(action, np.float32), lam, et)
        )
        return StepScore(
            likelihood=float(out[0]),
            novelty=float(out[1]),
            compatibility=float(out[2]),
            incompatible=bool(out[3] > 0.5),
            policy_action=np.clip(out[4:], -1.0, 1.0),
        )
