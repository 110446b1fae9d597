"""Session configuration: a frozen dataclass with the paper's protocol as defaults.

Defaults (the paper's elicitation protocol): 3 practice episodes, a prompt of 5 base
demonstrations, the 5% accept/reject rule, feedback on the 3 worst windows of 10 steps with
L2 retrieval, retraining after each batch scored against the new policy.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elicit_jax.compat.thresholds import (
    SESSION_KEYS,
    Thresholds,
    from_session_fields,
    session_fields,
)
from elicit_jax.errors import ElicitError

MODES = ("informed", "naive")
SHOW_PARTS = ("prompt", "indicator", "feedback")
"""The parts of the informed interface: the prompt, the live indicator, post-hoc feedback."""
RETRIEVALS = ("l2", "dtw")
PATH_FIELDS = ("policy", "base_demos", "thresholds_file")
"""Settings naming input files: a resumed session compares the files' hashes, not the paths."""
STORED_THRESHOLDS = SESSION_KEYS
"""The keys a session header stores its :class:`Thresholds` under (see ``to_dict``)."""
EXTENDABLE = ("demos", "max_episodes")
"""Settings a resumed session may change (ask for more demonstrations or episodes)."""


@dataclasses.dataclass(frozen=True)
class SessionConfig:
    """How an elicitation session runs.

    Attributes:
      task: simulated task name.
      policy: base policy checkpoint (run or seed directory).
      base_demos: the base demonstrations D_base (demos artifact).
      thresholds: λ and η, and the thresholds file they came from, if any (stored in the
        session header as ``lambda``, ``eta`` and ``thresholds_file``).
      operator: operator spec, e.g. ``scripted:conflict-flip-pause``.
      mode: ``informed`` (prompt, live indicator, feedback, the rule applied) or ``naive``
        (the paper's control: practice only; the rule is computed and recorded, not applied).
      show: informed mode: the parts of the interface the operator gets (default all three;
        an ablation shows fewer). The rule is applied whatever is shown; a verdict and its
        feedback are shown only with ``feedback``.
      demos: demonstrations wanted (accepted).
      batch: retrain after every this many accepted demonstrations (0: never).
      fixed_base: score every batch against the base policy (else against the latest π_new).
      dagger: HG-DAgger: the policy acts, the operator takes over.
      practice: practice episodes first (recorded, never part of the demonstrations).
      prompt: base demonstrations shown in the prompt (informed mode).
      accept_fraction: the paper's rule: reject above this fraction of incompatible pairs.
      reject_count: the original code's rule: reject above this many (None: use the fraction).
      window: feedback window length (steps).
      windows: feedback windows shown on a rejection.
      retrieval: ``l2`` (paper) or ``dtw`` (original code).
      likelihood: ``ensemble-mean`` (paper) or ``member-average``.
      ddof: novelty std convention (0 paper, 1 original code).
      which: checkpoint of the policy: ``best``, ``final`` or an epoch.
      policy_seed: seed of a multi-seed run directory (None: its only seed).
      seed: session seed (initial states, operator randomness).
      max_episodes: stop after this many episodes, practice included (0: practice + 5 × demos).
      horizon: control steps per episode (0: the task's).
    """

    task: str
    policy: str
    base_demos: str
    thresholds: Thresholds
    operator: str
    mode: str = "informed"
    show: tuple[str, ...] = SHOW_PARTS
    demos: int = 10
    batch: int = 0
    fixed_base: bool = False
    dagger: bool = False
    practice: int = 3
    prompt: int = 5
    accept_fraction: float = 0.05
    reject_count: int | None = None
    window: int = 10
    windows: int = 3
    retrieval: str = "l2"
    likelihood: str = "ensemble-mean"
    ddof: int = 0
    which: str = "best"
    policy_seed: int | None = None
    seed: int = 0
    max_episodes: int = 0
    horizon: int = 0

    def __post_init__(self) -> None:
        show = (self.show,) if isinstance(self.show, str) else tuple(self.show)
        object.__setattr__(self, "show", show)
        bad = [p for p in show if p not in SHOW_PARTS]
        if bad or len(set(show)) != len(show):
            raise ElicitError(
                f"--show takes distinct parts among {', '.join(SHOW_PARTS)}, got {','.join(show)}"
            )
        checks = (
            (self.mode in MODES, f"--mode must be one of {', '.join(MODES)}, got {self.mode!r}"),
            (self.demos >= 1, f"--demos must be >= 1, got {self.demos}"),
            (self.batch >= 0, f"--batch must be >= 0, got {self.batch}"),
            (self.practice >= 0, f"--practice must be >= 0, got {self.practice}"),
            (self.prompt >= 0, f"--prompt must be >= 0, got {self.prompt}"),
            (self.window >= 1, f"--window must be >= 1, got {self.window}"),
            (self.windows >= 1, f"--windows must be >= 1, got {self.windows}"),
            (
                self.retrieval in RETRIEVALS,
                f"--retrieval must be one of {', '.join(RETRIEVALS)}, got {self.retrieval!r}",
            ),
            (self.max_episodes >= 0, f"--max-episodes must be >= 0, got {self.max_episodes}"),
            (self.horizon >= 0, f"--horizon must be >= 0, got {self.horizon}"),
            (self.seed >= 0, f"--seed must be >= 0, got {self.seed}"),
            (":" in self.operator, f"operator must look like KIND:NAME, got {self.operator!r}"),
        )
        for ok, msg in checks:
            if not ok:
                raise ElicitError(msg)
        if not isinstance(self.thresholds, Thresholds):
            raise ElicitError(f"thresholds must be a Thresholds value, got {self.thresholds!r}")
        self.rule()  # validates the fraction and the count
        self.score_config()

    def shown(self, part: str) -> bool:
        """The operator gets ``part`` (``prompt``, ``indicator``, ``feedback``)."""
        return self.mode == "informed" and part in self.show

    @property
    def episode_limit(self) -> int:
        """Most episodes the session records (practice included)."""
        return self.max_episodes or self.practice + 5 * self.demos

    def rule(self) -> Any:
        """The accept/reject rule."""
        from elicit_jax.elicit.rules import AcceptRule

        return AcceptRule(fraction=self.accept_fraction, count=self.reject_count)

    def score_config(self) -> Any:
        """The :class:`~elicit_jax.compat.measures.ScoreConfig` of the live scorer."""
        from elicit_jax.compat.measures import ScoreConfig

        return ScoreConfig(
            likelihood=self.likelihood,  # type: ignore[arg-type]
            ddof=self.ddof,
            thresholds=self.thresholds,
            accept_fraction=self.accept_fraction,
        )

    def init_seed(self, episode: int) -> int:
        """Simulator seed of episode ``episode``'s initial state: a hash of the session seed
        and the index (31 bits), so sessions do not replay ``collect``'s initial states
        (``seed * 100000 + attempt``) and a resumed session repeats its own."""
        return zlib.crc32(f"session|{self.seed}|{episode}".encode()) & 0x7FFFFFFF

    def with_absolute_paths(self) -> SessionConfig:
        """The config with its input paths made absolute (a session resumes from anywhere)."""
        t = self.thresholds
        if t.file is not None:
            t = dataclasses.replace(t, file=Path(t.file).absolute())
        return dataclasses.replace(
            self,
            policy=str(Path(self.policy).absolute()),
            base_demos=str(Path(self.base_demos).absolute()),
            thresholds=t,
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict, as the session header stores it: the thresholds as ``lambda``,
        ``eta`` and ``thresholds_file`` (the layout sessions have always been written in)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        t = d.pop("thresholds")
        d["show"] = list(self.show)
        return d | session_fields(t)

    @classmethod
    def from_dict(
        cls, data: Mapping[str, Any], thresholds: Thresholds | None = None
    ) -> SessionConfig:
        """Inverse of :meth:`to_dict`; unknown keys are an error.

        Args:
          data: the settings, the thresholds as :data:`STORED_THRESHOLDS` (``lambda_`` is
            read as ``lambda``).
          thresholds: thresholds resolved by the caller; they replace those in ``data``.
        """
        d = dict(data)
        stored = dict(d)
        for k in (*STORED_THRESHOLDS, "lambda_"):
            d.pop(k, None)
        if thresholds is None:
            thresholds = from_session_fields(stored)
        settings = {f.name for f in dataclasses.fields(cls)} - {"thresholds"}
        unknown = set(d) - settings
        if unknown:
            raise ElicitError(f"unknown session config key(s): {', '.join(sorted(unknown))}")
        return cls(**d, thresholds=thresholds)

    def differences(self, other: SessionConfig) -> list[str]:
        """Names of the settings (not input paths) that differ from ``other``."""
        a, b = self.to_dict(), other.to_dict()
        skip = (*PATH_FIELDS, *EXTENDABLE)
        return sorted(k for k in a if k not in skip and a[k] != b.get(k))


PERSON_MARGIN = 4.0
"""A person's episodes may last this many times the base demonstrations' 95th-percentile length."""
PERSON_ROUND = 20


def person_horizon(task_horizon: int, base_lengths: Sequence[int]) -> int:
    """Control steps a person at a keyboard gets per episode, from the base demonstrations.

    The base operator is proficient (and scripted, in the shipped tasks): it moves every axis
    at once at full speed. A person presses one or two keys at a time, overshoots and slows
    down near the goal (Shift), so the horizon is ``PERSON_MARGIN`` (4) × the 95th percentile
    of the base lengths, rounded up to a multiple of 20 steps (whole seconds at 20 Hz), and
    never shorter than the task's own horizon. On reach-pillar (base lengths 38–45 steps)
    that is 180 steps (9 s) instead of 100 (5 s).

    Args:
      task_horizon: the task's horizon (steps).
      base_lengths: lengths of the base demonstrations (steps).

    Returns:
      The horizon in control steps.
    """
    lengths = np.asarray(base_lengths, np.float64)
    if lengths.size == 0:
        return int(task_horizon)
    want = PERSON_MARGIN * float(np.percentile(lengths, 95))
    return max(int(task_horizon), int(math.ceil(want / PERSON_ROUND) * PERSON_ROUND))
