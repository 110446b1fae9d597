"""CUPID (Agia et al., CoRL 2025, "Curating Data your Robot Loves with Influence Functions"):
estimate each demonstration's influence on the policy's expected return from its own scored
rollouts, and drop the demonstrations estimated to lower it.

The estimator, for a policy trained by behaviour cloning with a per-pair loss ℓ:

1. **Policy gradient from rollouts.** With Gaussian exploration noise around the policy's
   action, ``log π(a | s) = −c · ℓ̄(s, a) + const`` where ℓ̄ is the squared error of the
   ensemble mean (c > 0), so REINFORCE gives ``∇J ∝ −(1/m) Σ_j R_j Σ_t ∇ℓ̄(s_jt, a_jt)`` over
   m rollouts with return ``R_j`` (+1 success, −1 failure). Deterministic rollouts (no noise)
   have ``a = π̄(s)``, a zero gradient and no signal: record them with ``--action-noise``.
2. **Influence of a training pair.** Up-weighting a training pair x moves each member's
   parameters by ``−H_k⁻¹ ∇ℓ_k(x)`` (ℓ_k: member k's own training loss), so the return changes
   by ``Σ_k g_kᵀ H_k⁻¹ ∇ℓ_k(x)`` with ``g_k = (1/m) Σ_j R_j Σ_t ∇_θk ℓ̄(s_jt, a_jt)``.
3. **TRAK's approximations.** Per-sample gradients (``vmap(grad)``) of every training pair of
   D_base ∪ D_new are randomly projected to ``proj_dim`` dims (a Rademacher matrix generated in
   chunks from a seed, never stored whole); the Hessian is the Gauss-Newton matrix of the
   projected gradients ``Φ_kᵀΦ_k``, damped by ``damping`` times its mean diagonal. Members
   whose parameter count is at most ``proj_dim`` use the exact gradients.
4. **Demonstration score** = the mean influence of its pairs (positive: estimated to raise the
   expected return). The method's own cut drops every D_new demonstration with a negative
   score; ``--rate m`` drops the lowest until the M-filter's amount.

MLP ensembles only (MDN/LSTM losses differ). Gradients are taken in evaluation mode (no
dropout), at the checkpoint that was rolled out.

Example:
    >>> scores = cupid_scores(policy, steps, new, base, CupidConfig())
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.curation.episodes import EpisodeScores, episode_table
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.policy.base import Policy


@dataclasses.dataclass(frozen=True)
class CupidConfig:
    """CUPID settings.

    Attributes:
      proj_dim: random-projection dimension of the per-sample gradients (TRAK's k).
      damping: added to the projected Gauss-Newton matrix, relative to its mean diagonal.
      batch: training pairs per per-sample-gradient batch.
      chunk: parameters per generated block of the projection matrix.
      seed: seed of the projection.
      checkpoint: the checkpoint of the policy that was rolled out (``best``, ``final`` or an
        epoch).
      policy_seed: training seed of a multi-seed run (None: its first).
      action_noise: pipeline only: exploration noise of the rollouts it records.
      rollouts: pipeline only: rollouts it records.
      rollout_seed: pipeline only: the evaluation seed of their initial states (far from the
        evaluation's own, 0 and 1, and Demo-SCORE's, 50 and up).
    """

    proj_dim: int = 512
    damping: float = 0.1
    batch: int = 256
    chunk: int = 16384
    seed: int = 0
    checkpoint: str = "best"
    policy_seed: int | None = None
    action_noise: float = 0.1
    rollouts: int = 50
    rollout_seed: int = 40

    def __post_init__(self) -> None:
        object.__setattr__(self, "checkpoint", str(self.checkpoint))
        if self.proj_dim < 1 or self.batch < 1 or self.chunk < 1:
            raise ElicitError("cupid: proj_dim, batch and chunk must be positive")
        if not (np.isfinite(self.damping) and self.damping > 0):
            raise ElicitError(f"cupid: damping must be a positive number, got {self.damping}")
        if not (np.isfinite(self.action_noise) and self.action_noise > 0):
            raise ElicitError(f"cupid: action_noise must be > 0, got {self.action_noise}")
        if self.rollouts < 2:
            raise ElicitError(f"cupid: rollouts must be at least 2, got {self.rollouts}")


def _projector(dim: int, config: CupidConfig) -> tuple[Any, int]:
    """``project(g (B, dim)) -> (B, p)`` and p: a seeded Rademacher projection scaled by
    1/sqrt(p), generated block by block; the identity when ``dim <= proj_dim``."""
    import jax
    import jax.numpy as jnp

    p = int(config.proj_dim)
    if dim <= p:
        return (lambda g: g), dim
    chunk = min(int(config.chunk), dim)
    n = -(-dim // chunk)
    key = jax.random.key(config.seed)

    def project(g: Any) -> Any:
        g = jnp.pad(g, ((0, 0), (0, n * chunk - dim))).reshape(g.shape[0], n, chunk)

        def body(acc: Any, xs: tuple[Any, Any]) -> tuple[Any, None]:
            i, block = xs
            mat = jax.random.rademacher(jax.random.fold_in(key, i), (chunk, p), jnp.float32)
            return acc + block @ mat, None

        init = jnp.zeros((g.shape[0], p), jnp.float32)
        out, _ = jax.lax.scan(body, init, (jnp.arange(n), jnp.swapaxes(g, 0, 1)))
        return out / jnp.sqrt(jnp.float32(p))

    return project, p


def _member_fns(policy: Policy) -> tuple[Any, Any, int]:
    """``train_grads(params_k, x, a) -> (B, D)`` per-sample gradients of member k's loss,
    ``test_grad(params, x, a, w) -> (K, D)`` gradient of Σ w·ℓ̄ per member, and D."""
    import jax
    import jax.numpy as jnp
    from jax.flatten_util import ravel_pytree

    module = policy.module
    one = jax.tree.map(lambda leaf: leaf[0], policy.params)
    dim = int(ravel_pytree(one)[0].size)

    def member_loss(p: Any, x: Any, a: Any) -> Any:
        pred = module.apply({"params": p}, x[None], False)[0]
        return jnp.mean((pred - a) ** 2)

    def train_grads(p: Any, x: Any, a: Any) -> Any:
        grads = jax.vmap(jax.grad(member_loss), in_axes=(None, 0, 0))(p, x, a)
        return jax.vmap(lambda g: ravel_pytree(g)[0])(grads)

    def weighted_mean_loss(params: Any, x: Any, a: Any, w: Any) -> Any:
        preds = jax.vmap(lambda p: module.apply({"params": p}, x, False))(params)
        return jnp.sum(w * jnp.mean((jnp.mean(preds, axis=0) - a) ** 2, axis=-1))

    def test_grad(params: Any, x: Any, a: Any, w: Any) -> Any:
        g = jax.grad(weighted_mean_loss)(params, x, a, w)
        return jax.vmap(lambda gk: ravel_pytree(gk)[0])(g)

    return jax.jit(train_grads), jax.jit(test_grad), dim


def rollout_gradient(policy: Policy, steps: Any, config: CupidConfig, test_grad: Any) -> np.ndarray:
    """``(K, D)`` per-member ``g_k = (1/m) Σ_j R_j Σ_t ∇ℓ̄(s_jt, a_jt)`` over the rollouts,
    ``R`` = +1 for a success and −1 for a failure."""
    import jax.numpy as jnp

    m = len(steps.success)
    r = np.where(np.asarray(steps.success, bool), 1.0, -1.0)
    w = (r[steps.rollout] / m).astype(np.float32)
    x = np.asarray(policy.normalize(jnp.asarray(steps.obs)), np.float32)
    total = None
    for lo in range(0, len(w), config.batch):
        hi = lo + config.batch
        g = np.asarray(test_grad(policy.params, x[lo:hi], steps.action[lo:hi], w[lo:hi]))
        total = g if total is None else total + g
    return np.asarray(total, np.float64)


def pair_influence(
    policy: Policy, obs: np.ndarray, action: np.ndarray, steps: Any, config: CupidConfig
) -> tuple[np.ndarray, dict[str, Any]]:
    """``(N,)`` estimated influence of each training pair on the expected return, summed over
    members, and diagnostics."""
    import jax
    import jax.numpy as jnp

    if policy.kind != "mlp":
        raise ElicitError(f"cupid scores MLP ensembles, not a '{policy.kind}' policy")
    train_grads, test_grad, dim = _member_fns(policy)
    project, p = _projector(dim, config)
    project = jax.jit(project)
    g = rollout_gradient(policy, steps, config, test_grad)
    x = np.asarray(policy.normalize(jnp.asarray(obs)), np.float32)
    a = np.asarray(action, np.float32)
    infl = np.zeros(len(x))
    for k in range(policy.n_members):
        pk = jax.tree.map(lambda leaf, k=k: leaf[k], policy.params)
        b = config.batch
        phi = np.concatenate(
            [
                np.asarray(project(train_grads(pk, x[lo : lo + b], a[lo : lo + b])))
                for lo in range(0, len(x), b)
            ]
        ).astype(np.float64)
        gk = np.asarray(project(jnp.asarray(g[k][None], jnp.float32)), np.float64)[0]
        gram = phi.T @ phi
        gram += config.damping * max(float(np.trace(gram)) / p, 1e-12) * np.eye(p)
        infl += phi @ np.linalg.solve(gram, gk)
    report = {
        "param_dim": dim,
        "proj_dim": p,
        "projected": dim > config.proj_dim,
        "rollout_grad_norm": float(np.linalg.norm(g)),
    }
    return infl, report


def cupid_scores(
    policy: Policy, steps: Any, new: Any, base: Any = None, config: CupidConfig = CupidConfig()
) -> EpisodeScores:
    """CUPID scores of the demonstrations of ``new`` (mean influence of their pairs on the
    expected return of ``policy``, estimated from its recorded rollouts ``steps``).

    Args:
      policy: the ensemble trained on ``base ∪ new`` and rolled out.
      steps: :class:`~elicit_jax.sim.trajectories.Trajectories` of its rollouts.
      new: :class:`~elicit_jax.data.demos.Demos` to score (D_new).
      base: D_base, part of the training set (the Hessian) but not scored.
      config: estimator settings.
    """
    parts = [new] if base is None else [base, new]
    for d in parts:
        if (d.obs_dim, d.action_dim) != (policy.obs_dim, policy.action_dim):
            raise ElicitError(
                f"demos have obs/action dims {d.obs_dim}/{d.action_dim}, the policy "
                f"{policy.obs_dim}/{policy.action_dim}"
            )
    if steps.obs.shape[1] != policy.obs_dim or steps.action.shape[1] != policy.action_dim:
        raise ElicitError("rollout trajectories do not match the policy's obs/action dims")
    obs = np.concatenate([d.obs for d in parts])
    action = np.concatenate([d.action for d in parts])
    infl, report = pair_influence(policy, obs, action, steps, config)
    if not np.isfinite(infl).all():
        raise ElicitError("cupid: non-finite influence estimates (diverged gradients?)")
    n_base = 0 if base is None else base.n_steps
    ids, ops, length, index = episode_table(new.episode, new.operator)
    score = np.bincount(index, weights=infl[n_base:], minlength=len(ids)) / length
    report |= {
        "rollouts": len(steps.success),
        "rollout_successes": int(np.sum(steps.success)),
        "rollout_steps": len(steps.rollout),
        "action_noise": float(steps.action_noise),
        "n_train_pairs": len(obs),
        "negative_demos": int((score < 0).sum()),
    }
    why = _no_signal(report, float(steps.action_noise))
    if why:
        return EpisodeScores(
            "cupid", ids, ops, length, np.zeros(len(ids)), report={**report, "why": why},
            trusted=False,
        )  # fmt: skip
    return EpisodeScores("cupid", ids, ops, length, score, threshold=0.0, report=report)


def _no_signal(report: dict[str, Any], action_noise: float) -> str:
    """Why the rollouts carry no policy-gradient signal, or "" when they do."""
    if action_noise <= 0 or report["rollout_grad_norm"] == 0.0:
        return "the rollouts carry no exploration noise, so their policy gradient is zero"
    m, wins = report["rollouts"], report["rollout_successes"]
    if wins in (0, m):
        outcome = "failed" if wins == 0 else "succeeded"
        return (
            f"all {m} rollouts {outcome}: with a return that does not vary the policy-gradient "
            "estimate has mean zero, so every influence is noise; record rollouts with both "
            "outcomes (more rollouts, or another --action-noise)"
        )
    return ""


def cupid_file_scores(
    policy_path: Any, trajectories_path: Any, new: Any, base: Any, config: CupidConfig
) -> EpisodeScores:
    """:func:`cupid_scores` of the ``config.checkpoint`` of a training run (its
    ``config.policy_seed``, default the first) against its recorded rollouts of that seed and
    checkpoint."""
    from elicit_jax.policy.checkpoint import list_checkpoints
    from elicit_jax.policy.loaded import load_policy
    from elicit_jax.sim.trajectories import read_trajectories

    avail = list_checkpoints(policy_path)
    seed = min(avail) if config.policy_seed is None else int(config.policy_seed)
    if seed not in avail:
        raise ElicitError(f"cupid: no training seed {seed} (have {sorted(avail)})", policy_path)
    which: str | int = int(config.checkpoint) if config.checkpoint.isdigit() else config.checkpoint
    policy = load_policy(policy_path, which, seed=seed).policy
    steps = read_trajectories(trajectories_path, None, seed, config.checkpoint)
    return cupid_scores(policy, steps, new, base, config)
