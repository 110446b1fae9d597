"""Live compatibility at control rate: ONE compiled single-state scorer per session.

:class:`LiveScorer` jits, once, a function of ``(policy, obs (O,), action (A,), inputs,
step)`` that runs the batch scorer's own per-chunk function
(:func:`elicit_jax.compat.scorer.score_rows`: the policy's members, then
:func:`elicit_jax.compat.measures.score_pair`) on a chunk of ONE pair — so a live score is
``elicit-jax score``'s score, with the same definitions and options (likelihood kind, ddof,
clipping bounds, action scaling, MC-dropout). The policy and the numbers (thresholds,
bounds, weights) are arguments, not constants, so a retrained policy of the same
architecture (π_new between batches), a new episode or new thresholds reuse the compiled
function: nothing recompiles during a session (:attr:`LiveScorer.traces` counts the traces
and stays 1). Everything comes back in one small host transfer.

Only feed-forward policies (``mlp``, ``mdn``) can be scored one state at a time; an LSTM's
score depends on the whole history and is refused with a clear error.

Example:
    >>> scorer = LiveScorer(ScoreConfig(thresholds=Thresholds(0.4, 0.05, "given")), policy)
    >>> s = scorer.score(policy, obs, action)     # StepScore(likelihood, novelty, ...)
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.compat.measures import ScoreConfig
from elicit_jax.compat.thresholds import Thresholds
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.policy.base import Policy


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


def check_live_policy(policy: Policy, source: str = "<policy>") -> None:
    """Raise unless ``policy`` can be scored one state at a time (a feed-forward kind)."""
    from elicit_jax.policy.kinds import MODEL_KINDS, model_kind

    kind = model_kind(policy.kind)
    if kind.recurrent:
        feed_forward = " or ".join(k.name for k in MODEL_KINDS.values() if not k.recurrent)
        raise ElicitError(
            f"live scoring needs a feed-forward policy ({feed_forward}); this one is an "
            f"{kind.name}, whose scores depend on the whole episode (score its demonstrations "
            "with `score`)",
            source,
        )


class LiveScorer:
    """One compiled single-state scorer (see the module docstring).

    Args:
      config: the score config (likelihood kind, ddof, clip, action scale, MC-dropout; its
        thresholds are the defaults of :meth:`score`).
      policy: the policy the scorer starts with (its action weights, for ``action_scale``).
      bounds: the demonstrations' action bounds ``(low, high)``, the ``member-average``
        clipping range unless ``config.clip`` is set (as ``score`` does).
      source: the policy's name in error messages.

    Attributes:
      traces: times the scoring function was traced (1 after the first call, if nothing
        recompiled).
    """

    def __init__(
        self,
        config: ScoreConfig,
        policy: Policy,
        bounds: tuple[Any, Any] | None = None,
        source: str = "<policy>",
    ) -> None:
        import jax
        import jax.numpy as jnp

        from elicit_jax.compat.scorer import score_inputs, score_rows, static_config

        self.config = config
        self.traces = 0
        self.inputs = score_inputs(policy, config, bounds, source)
        static = static_config(config)

        def one(policy: Policy, obs: Any, action: Any, inputs: Any, step: Any) -> Any:
            self.traces += 1
            s = score_rows(policy, obs[None], action[None], inputs, step, static)
            head = jnp.stack(
                [s.likelihood[0], s.novelty[0], s.compatibility[0], s.incompatible[0]]
            ).astype(jnp.float32)
            return jnp.concatenate([head, s.mean[0].astype(jnp.float32)])

        self._fn = jax.jit(one)

    def score(
        self,
        policy: Policy,
        obs: np.ndarray,
        action: np.ndarray,
        thresholds: Thresholds | None = None,
        step: int = 0,
    ) -> StepScore:
        """Score ``action (A,)`` at state ``obs (O,)`` under ``policy``.

        Args:
          policy: a feed-forward :class:`~elicit_jax.policy.base.Policy`.
          obs: (O,) state.
          action: (A,) action (for the policy's action alone, pass zeros and read
            ``policy_action``).
          thresholds: (λ, η) for this call (default the config's).
          step: the pair's index (keys the MC-dropout masks, as a row index does in
            ``score``).

        Raises:
          ElicitError: the policy's prediction is not finite (a NaN would read as M = 1).
        """
        import jax.numpy as jnp

        inputs = self.inputs
        if thresholds is not None:
            lam, et = thresholds.pair
            inputs = inputs.replace(lam=jnp.float32(lam), eta=jnp.float32(et))
        out = np.asarray(
            self._fn(
                policy,
                np.asarray(obs, np.float32),
                np.asarray(action, np.float32),
                inputs,
                np.int32(step),
            )
        )
        if not np.isfinite(out[:2]).all():
            raise ElicitError(
                "the policy's prediction is not finite (NaN or inf): the checkpoint is corrupt "
                "or its training diverged"
            )
        return StepScore(
            likelihood=float(out[0]),
            novelty=float(out[1]),
            compatibility=float(out[2]),
            incompatible=bool(out[3] > 0.5),
            policy_action=np.clip(out[4:], -1.0, 1.0),
        )
