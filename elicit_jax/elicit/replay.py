"""Exact replay of recorded session episodes (C MuJoCo, or the task's robosuite environment).

An episode file holds the initial-state seed, the applied actions and the simulator state
(``qpos``, ``qvel``) each step started from. :func:`replay_episode` re-runs the actions from
the seeded initial state and returns the states it passes through (MuJoCo is deterministic
and robosuite's controller too: they equal the recorded ones bit for bit); :func:`set_state` puts a
simulator at any recorded step, e.g. to render the frames of a feedback window.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def replay_episode(task: Any, record: Any) -> dict[str, np.ndarray]:
    """Replay ``record`` (an :class:`~elicit_jax.elicit.store.EpisodeRecord`) on ``task``.

    Returns:
      ``qpos (T, nq)`` and ``qvel (T, nv)`` each step started from, ``obs (T, O)``, and
      ``success`` (bool) after the last step.
    """
    from elicit_jax.sim.single import open_env

    qpos, qvel, obs = [], [], []
    with open_env(task) as sim:
        sim.reset_seeds(np.array([record.init_seed]))
        for a in np.asarray(record.action, np.float64):
            d = sim.datas[0]
            qpos.append(d.qpos.copy())
            qvel.append(d.qvel.copy())
            obs.append(sim.obs[0].copy())
            sim.step(a[None])
        success = bool(sim.success[0])
        nq, nv = sim.model.nq, sim.model.nv
    return {
        "qpos": np.array(qpos).reshape(-1, nq),
        "qvel": np.array(qvel).reshape(-1, nv),
        "obs": np.array(obs).reshape(len(obs), -1),
        "success": np.array(success),
    }


def set_state(task: Any, data: Any, record: Any, step: int) -> None:
    """Put MuJoCo ``data`` at the state recorded before ``step`` (positions, velocities)."""
    import mujoco

    data.qpos[:] = record.qpos[step]
    data.qvel[:] = record.qvel[step]
    mujoco.mj_forward(task.mj_model, data)
