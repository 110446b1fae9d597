"""Everything a session needs, loaded and checked once: task, base data, policies, scorer, store.

:func:`open_session` validates the inputs (task, base demonstrations, policy, thresholds,
operator) before touching the output directory, then creates the session directory or
resumes the one there (:mod:`elicit_jax.elicit.session_dir`). A robosuite task is opened
like any other; its environment is built in this process when the first episode begins.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from elicit_jax.artifact import make_header, read_header
from elicit_jax.elicit.config import SessionConfig
from elicit_jax.elicit.events import PRACTICE, PromptEpisode, PromptEvent, RetrainEvent
from elicit_jax.elicit.explain import explain_episode, summary_text
from elicit_jax.elicit.inputs import load_inputs, task_action_names
from elicit_jax.elicit.live import LiveScorer
from elicit_jax.elicit.progress import Progress
from elicit_jax.elicit.rules import AcceptRule
from elicit_jax.elicit.session_dir import absolute_inputs, open_store, session_inputs
from elicit_jax.elicit.store import SCHEMA_VERSION, SESSION_KIND, EpisodeRecord, SessionStore
from elicit_jax.errors import ElicitError

if TYPE_CHECKING:
    from elicit_jax.policy.loaded import LoadedPolicy


def _segments(mask: np.ndarray) -> int:
    """Number of runs of True in a (T,) bool array."""
    m = np.asarray(mask, bool)
    return int(np.sum(m[1:] & ~m[:-1]) + (m[0] if len(m) else 0))


@dataclasses.dataclass
class SessionSetup:
    """Loaded resources of a session (built by :func:`open_session`)."""

    config: SessionConfig
    store: SessionStore
    task: Any
    base: Any
    base_policy: LoadedPolicy
    policy: LoadedPolicy
    train_config: Any
    scorer: LiveScorer
    rule: AcceptRule
    action_names: tuple[str, ...]
    quiet: bool = True
    policy_batch: int = 0
    stats: tuple[np.ndarray, np.ndarray] | None = None
    _accepted: dict[int, dict[str, np.ndarray]] = dataclasses.field(default_factory=dict)
    _prompt: PromptEvent | None = None

    @property
    def obs_dim(self) -> int:
        return int(self.base.obs_dim)

    @property
    def action_dim(self) -> int:
        return int(self.base.action_dim)

    # --- review ------------------------------------------------------------------------------
    def judge(self, rec: EpisodeRecord, progress: Progress) -> EpisodeRecord:
        """Fill in the verdict, the rule's verdict, feedback and text of a finished episode."""
        c = self.config
        meta = {**rec.meta, "dagger": c.dagger, "interventions": _segments(rec.operator)}
        if rec.kind == PRACTICE:
            return dataclasses.replace(rec, verdict="practice", text="practice", meta=meta)
        scored, n_inc = rec.n_scored, rec.n_incompatible
        rule_verdict = (
            "" if not scored else "reject" if self.rule.rejects(n_inc, scored) else "accept"
        )
        if not scored:
            verdict = "unused" if rec.success else "failed"
        elif not rec.success:
            verdict = "failed"
        elif c.mode == "informed":
            verdict = "accepted" if rule_verdict == "accept" else "rejected"
        else:
            verdict = "accepted"
        feedback: tuple = ()
        if rule_verdict == "reject" and rec.success:
            m = rec.scored
            feedback = tuple(
                explain_episode(
                    rec.compatibility[m],
                    rec.obs[m],
                    rec.action[m],
                    self.base,
                    action_names=self.action_names,
                    window=c.window,
                    k=c.windows,
                    method=c.retrieval,
                    stats=self.stats,
                )
            )
        if verdict == "failed" and rec.meta.get("gave_up"):
            text = f"failed: gave up after {rec.length} steps"
        elif verdict == "failed":
            text = f"failed: the task was not completed in {rec.length} steps"
        elif verdict == "unused":
            text = "the robot finished without an intervention: nothing to record"
        else:
            text = summary_text(verdict, n_inc, scored, self.rule.describe(), feedback)
            if c.mode == "naive" and rule_verdict == "reject":
                text += " (naive mode: the rule's verdict is recorded, not applied)"
        return dataclasses.replace(
            rec,
            batch=progress.batch_of_next(c.batch),
            verdict=verdict,
            rule_verdict=rule_verdict,
            feedback=feedback,
            feedback_shown=c.shown("feedback"),
            text=text,
            meta=meta,
        )

    def prompt_event(self) -> PromptEvent:
        """The prompt: the base demonstrations the base policy fits best (lowest mean ℓ)."""
        if self._prompt is None:
            from elicit_jax.compat.score import score_demos

            scores = score_demos(self.base_policy.policy, self.base, self.config.score_config())
            ids, index = np.unique(self.base.episode, return_inverse=True)
            mean_ell = np.bincount(index, weights=scores["likelihood"]) / np.bincount(index)
            order = np.lexsort((ids, mean_ell))[: self.config.prompt]
            rows = {e: (s, t) for e, s, t in self.base.episode_bounds()}
            seeds = self.base.extra.get("init_seed")
            eps = []
            for i in order:
                s, t = rows[int(ids[i])]
                eps.append(
                    PromptEpisode(
                        base_episode=int(ids[i]),
                        obs=self.base.obs[s:t],
                        action=self.base.action[s:t],
                        init_seed=int(seeds[s]) if seeds is not None else -1,
                        mean_likelihood=float(mean_ell[i]),
                    )
                )
            self._prompt = PromptEvent(
                tuple(eps),
                f"the {len(eps)} base demonstrations the policy reproduces best: do it like this",
            )
        return self._prompt

    # --- outputs -----------------------------------------------------------------------------
    def _accepted_episode(self, index: int) -> dict[str, np.ndarray]:
        if index not in self._accepted:
            rec = self.store.read_episode(index)
            op = np.asarray(rec.operator, bool)
            n = int(op.sum())
            reward = np.zeros(n, np.float32)
            reward[-1] = 1.0
            self._accepted[index] = {
                "obs": rec.obs[op],
                "action": rec.action[op],
                "reward": reward,
                "init_seed": np.full(n, rec.init_seed, np.int64),
                "session_episode": np.full(n, rec.index, np.int64),
                "source_step": np.flatnonzero(op).astype(np.int32),
                "intervention": np.full(n, self.config.dagger),
            }
        return self._accepted[index]

    def accepted_demos(self, indices: tuple[int, ...]) -> Any:
        """The accepted episodes ``indices`` as ``Demos`` (the operator's steps only)."""
        from elicit_jax.data.demos import from_episodes

        name = self.config.operator.partition(":")[2]
        return from_episodes(
            [self._accepted_episode(i) for i in indices],
            operators=name,
            task=self.base.task,
            obs_fields=self.base.obs_fields,
            action_low=-1.0,
            action_high=1.0,
            provenance={
                "source": "elicit-jax elicit",
                "session": str(self.store.root),
                "operator": self.config.operator,
                "mode": self.config.mode,
                "dagger": self.config.dagger,
            },
        )

    def write_demos(self, progress: Progress) -> None:
        """(Re)write the session's demos artifact from its accepted episodes."""
        from elicit_jax.data.demos import write_demos

        if not progress.accepted:
            return
        write_demos(
            self.store.demos_path,
            self.accepted_demos(progress.accepted),
            config=self.config.to_dict(),
            seed=self.config.seed,
        )

    def demos_up_to_date(self, progress: Progress) -> bool:
        path = self.store.demos_path
        if not progress.accepted:
            return True
        try:
            return int(read_header(path).get("n_episodes", -1)) == len(progress.accepted)
        except ElicitError:
            return False

    def write_manifest(self, progress: Progress) -> None:
        from elicit_jax.elicit.events import to_jsonable

        self.store.write_manifest(
            {
                "kind": "elicit-session-manifest",
                "note": "derived from episodes/*.parquet; the episode files are the record",
                "counts": to_jsonable(progress.counts),
                "policy_batch": self.policy_batch,
                "episodes": list(progress.rows),
            }
        )

    # --- retraining ---------------------------------------------------------------------------
    def catch_up_policies(self, progress: Progress, emit: Any) -> None:
        """Train every batch policy the accepted demonstrations call for and load the latest
        (unless the base stays fixed)."""
        from elicit_jax.elicit.retrain import train_batch_policy
        from elicit_jax.policy.loaded import load_policy

        c = self.config
        if not c.batch:
            return
        done = progress.counts.accepted // c.batch
        scoring = "base" if c.fixed_base else "new"
        for b in range(1, done + 1):
            out = self.store.policy_dir(b)
            if (out / "artifact.json").exists():
                continue
            demos = self.accepted_demos(progress.accepted[: b * c.batch])
            emit(RetrainEvent(b, b * c.batch, str(out), "start", scoring))
            train_batch_policy(
                out, self.base, demos, self.train_config, {"base_demos": c.base_demos}, self.quiet
            )
            emit(RetrainEvent(b, b * c.batch, str(out), "done", scoring))
        if done and not c.fixed_base and self.policy_batch != done:
            self.policy = load_policy(self.store.policy_dir(done), c.which)
            self.policy_batch = done


def _header(config: SessionConfig, inputs: dict[str, str], loaded: dict[str, Any]) -> dict:
    """The session directory's self-describing header."""
    from elicit_jax.policy.checkpoint import policy_spec

    task, base, train_config = loaded["task"], loaded["base"], loaded["train_config"]
    return make_header(
        SESSION_KIND,
        SCHEMA_VERSION,
        config=config.to_dict(),
        inputs=inputs,
        seed=config.seed,
        task=task.name,
        task_config=dataclasses.asdict(task.config),
        obs_fields={f.name: [f.start, f.stop] for f in base.obs_fields},
        action_names=list(task_action_names(task)),
        policy_model=policy_spec(loaded["policy"].policy),
        policy_seed=loaded["seed"],
        train_config=None if train_config is None else train_config.to_dict(),
    )


def open_session(
    config: SessionConfig,
    out: str | Path,
    *,
    overwrite: bool = False,
    resume: bool = False,
    quiet: bool = True,
) -> tuple[SessionSetup, Any, bool]:
    """Load and check every input, then create or resume the session directory ``out``.

    Args:
      config: the session's settings.
      out: the session directory.
      overwrite: start an existing session in ``out`` again.
      resume: require an existing session in ``out`` (``--resume``).
      quiet: no training progress bars.

    Returns:
      ``(setup, operator, resumed)`` with the operator named by ``config.operator``.
    """
    from elicit_jax.compat.feedback import normalizer

    if resume and overwrite:
        raise ElicitError("choose one of --resume and --overwrite")
    config = absolute_inputs(config)
    loaded = load_inputs(config)
    task, base, policy = loaded["task"], loaded["base"], loaded["policy"]
    root = Path(out)
    if resume and not (root / "artifact.json").exists():
        raise ElicitError("holds no session to resume", root)
    inputs = session_inputs(config)
    store, resumed = open_store(root, config, inputs, _header(config, inputs, loaded), overwrite)
    setup = SessionSetup(
        config=config,
        store=store,
        task=task,
        base=base,
        base_policy=policy,
        policy=policy,
        train_config=loaded["train_config"],
        scorer=LiveScorer(
            config.score_config(),
            policy.policy,
            bounds=(base.action_low, base.action_high),
            source=config.policy,
        ),
        rule=config.rule(),
        action_names=task_action_names(task),
        quiet=quiet,
        stats=normalizer(base.obs),
    )
    return setup, loaded["operator"], resumed
