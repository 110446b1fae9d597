"""The task registry: one :class:`TaskEntry` per task — its factory, its scripted operators,
its paper thresholds.

This is the one list of task names. :func:`elicit_jax.sim.env.make_task` builds a task from
its entry's ``factory``; :mod:`elicit_jax.sim.operators` finds a task's styles through its
entry's ``operators``; :mod:`elicit_jax.compat.measures` reads the threshold presets
(``PRESETS``) from the entries' ``preset``. Adding a task is adding one entry here (and its
modules under ``sim/tasks/`` and ``sim/operators/``).

The paper's (λ, η) are data about a task, like its horizon, so they live with it here and
``compat/`` reads them (``sim/`` never imports ``compat/``). A task without a paper preset says
so, and why, in ``no_preset``: commands then borrow square-nut's values and say they did.

The factories and operator modules are named, not imported (:func:`elicit_jax.sim.env.make_task`
and :mod:`elicit_jax.sim.operators` import them): this module is data and imports nothing
heavy, so reading a preset or listing names does not load MuJoCo.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from types import MappingProxyType

from elicit_jax.errors import ElicitError

OBS_DIM = 23
"""Observation size of the simulated tasks (end-effector position 3, quaternion 4, gripper 2,
object 14)."""
ACTION_DIM = 7
"""Action size of the simulated tasks (delta position 3, delta rotation 3, gripper 1)."""


@dataclasses.dataclass(frozen=True)
class TaskEntry:
    """One task.

    Attributes:
      name: the task's name (``--task``; the task class's ``name``).
      factory: ``module:Class`` of the task class under ``elicit_jax.sim.tasks``.
      operators: module under ``elicit_jax.sim.operators`` holding its scripted styles
        (``STYLES``) and operator class (``OPERATOR_CLASS``).
      preset: the paper's (λ, η) for the task (averaged over action dims), or None.
      preset_aliases: other names of the task a demonstrations file may carry (robosuite's /
        the original code's environment names, lower case), which get its preset too.
      no_preset: why the task has no paper preset (empty when it has one).
      recorded_as: more names (lower case) a training set of this task may record, e.g. the
        robosuite environment a robomimic file names (its own name and ``preset_aliases``
        count too); :mod:`elicit_jax.sim.task_match` checks a policy's task with them.
      obs_dim: the observation size the task gives (a policy must take it).
      action_dim: the action size the task takes (a policy must predict it); the policy
        loader checks both against a checkpoint (:func:`elicit_jax.policy.loaded.load_policy`).
    """

    name: str
    factory: str
    operators: str
    preset: tuple[float, float] | None = None
    preset_aliases: tuple[str, ...] = ()
    no_preset: str = ""
    recorded_as: tuple[str, ...] = ()
    obs_dim: int = OBS_DIM
    action_dim: int = ACTION_DIM


_ROBOSUITE = (
    "none assigned so far (its demos borrow square-nut's values, with a warning), although the "
    "paper ran on robosuite's nut tasks and their imported demos (task NutAssembly*) get one"
)

TASKS: Mapping[str, TaskEntry] = MappingProxyType(
    {
        e.name: e
        for e in (
            TaskEntry(
                "reach-pillar",
                "reach_pillar:ReachPillar",
                "reach_pillar",
                no_preset="a toy task of this package, not in the paper",
            ),
            TaskEntry(
                "square-nut",
                "square_nut:SquareNut",
                "square_nut",
                preset=(0.4, 0.05),
                preset_aliases=("nutassemblysquare",),
            ),
            TaskEntry(
                "round-nut",
                "round_nut:RoundNut",
                "round_nut",
                preset=(0.35, 0.05),
                preset_aliases=("nutassemblyround",),
            ),
            TaskEntry(
                "hammer-drawer",
                "hammer_drawer:HammerDrawer",
                "hammer_drawer",
                preset=(0.35, 0.06),
                preset_aliases=("hammerplaceenv",),
            ),
            TaskEntry(
                "robosuite-square",
                "robosuite_nuts:RobosuiteSquare",
                "robosuite_nuts",
                no_preset=_ROBOSUITE,
                recorded_as=("nutassemblysquare",),
            ),
            TaskEntry(
                "robosuite-round",
                "robosuite_nuts:RobosuiteRound",
                "robosuite_nuts",
                no_preset=_ROBOSUITE,
                recorded_as=("nutassemblyround",),
            ),
        )
    }
)


def task_entry(name: str) -> TaskEntry:
    """The registry entry of task ``name``.

    Raises:
      ElicitError: unknown task (one line naming the known ones).
    """
    if name not in TASKS:
        raise ElicitError(f"unknown task '{name}' (known: {', '.join(sorted(TASKS))})")
    return TASKS[name]


def preset_table() -> dict[str, tuple[float, float]]:
    """Preset name (the task's name) -> the paper's (λ, η), for the tasks that have one."""
    return {e.name: e.preset for e in TASKS.values() if e.preset is not None}


def preset_names() -> dict[str, str]:
    """Every name a task's demonstrations may carry (its own, lower case, and its aliases) ->
    its preset's name, for the tasks that have one."""
    return {
        alias: e.name
        for e in TASKS.values()
        if e.preset is not None
        for alias in (e.name, *e.preset_aliases)
    }
