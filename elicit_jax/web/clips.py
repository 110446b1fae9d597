"""Pose clips for the page's replays: the prompt's base demonstrations, the flagged windows.

The prompt replays whole base demonstrations; a rejection's review replays each flagged
window of the operator's episode beside the base segment retrieved for it. Base
demonstrations are re-simulated once from their seeded initial state and actions (or, when
they carry no seed, posed from their observations, gripper only) and kept; an operator's
window is posed from the episode file's recorded joint positions.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from elicit_jax.elicit.events import PromptEvent, ReviewEvent
from elicit_jax.web.protocol import ROLE_BASE, ROLE_PROMPT, ROLE_YOURS, pack_clip
from elicit_jax.web.scene import clip_from_actions, clip_from_obs, clip_from_states


class ClipMaker:
    """Builds (and caches) clips of one task's base demonstrations and session episodes.

    Args:
      task: the simulated task.
      base: the base demonstrations (``Demos``).
    """

    def __init__(self, task: Any, base: Any) -> None:
        self.task, self.base = task, base
        self._base: dict[int, np.ndarray] = {}
        self._rows = {int(e): (s, t) for e, s, t in base.episode_bounds()}

    def base_episode(self, episode: int) -> np.ndarray:
        """Poses ``(T, nbody, 7)`` of base episode ``episode`` (row t: the state of step t)."""
        if episode not in self._base:
            s, t = self._rows[episode]
            seeds = self.base.extra.get("init_seed")
            if seeds is not None and int(seeds[s]) >= 0:
                clip = clip_from_actions(self.task, int(seeds[s]), self.base.action[s:t])[:-1]
            else:
                clip = clip_from_obs(self.task, self.base.obs[s:t])
            self._base[episode] = clip
        return self._base[episode]

    def prompt_clips(self, event: PromptEvent) -> list[bytes]:
        """One clip per prompt episode (role 0, id = its place in the prompt)."""
        return [
            pack_clip(self.base_episode(p.base_episode), ROLE_PROMPT, i)
            for i, p in enumerate(event.episodes)
        ]

    def review_clips(self, event: ReviewEvent, record: Any) -> list[bytes]:
        """Per flagged window: the operator's steps (role 1) and the base segment (role 2)."""
        steps = np.flatnonzero(record.scored)
        yours = clip_from_states(self.task, record.qpos, record.init_seed)
        out = []
        for i, w in enumerate(event.feedback):
            out.append(pack_clip(yours[steps[w.start : w.stop]], ROLE_YOURS, i))
            base = self.base_episode(w.base_episode)[w.base_start : w.base_stop]
            out.append(pack_clip(base, ROLE_BASE, i))
        return out
