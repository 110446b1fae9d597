"""One robosuite environment, built from a spec, with seeded resets and flat observations.

This module imports robosuite only inside its functions, so the core install never needs it.
An environment is described by a :class:`RobosuiteSpec` (what robomimic stores as a
dataset's ``env_args``: robosuite environment name and keyword arguments) plus the
observation keys a policy reads, concatenated in order into one vector. The robomimic key
``object`` is robosuite's ``object-state``.

Seeded initial states: robosuite draws the object placement and the robot's joint noise from
NumPy's global generator, so :func:`reset_seeded` seeds it with the rollout's initial-state
seed before ``reset``; the same seed gives the same initial state in any process. The first
observation is read with ``force_update`` (as robomimic's wrapper does): robosuite's cached
relative-pose observables are zero right after a reset otherwise.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from typing import Any

import numpy as np

from elicit_jax.errors import ElicitError

ROBOMIMIC_KEY_ALIASES = {"object": "object-state"}
"""robomimic observation key -> robosuite observation key, where they differ."""
_OFF_SCREEN = {
    "has_renderer": False,
    "has_offscreen_renderer": False,
    "use_camera_obs": False,
    "ignore_done": True,
    "hard_reset": False,
}
"""Keyword arguments forced for headless low-dimensional rollouts (no cameras; the episode
length is the caller's; the model is loaded once per process)."""


@dataclasses.dataclass(frozen=True)
class RobosuiteSpec:
    """A robosuite environment and the observation a policy reads from it.

    Attributes:
      env_name: robosuite environment, e.g. ``NutAssemblySquare``.
      env_kwargs_json: the remaining ``suite.make`` keyword arguments, as sorted JSON (robot,
        controller configuration, control rate, ...).
      obs_keys: observation keys (robomimic names) concatenated into the observation.
    """

    env_name: str
    env_kwargs_json: str
    obs_keys: tuple[str, ...]

    @property
    def env_kwargs(self) -> dict[str, Any]:
        return json.loads(self.env_kwargs_json)

    def env_args(self) -> dict[str, Any]:
        """robomimic's ``env_args`` for this environment (``type`` 1 is robosuite)."""
        return {"env_name": self.env_name, "type": 1, "env_kwargs": self.env_kwargs}


def spec_for(
    env_name: str,
    obs_keys: Sequence[str],
    robot: str = "Panda",
    control_freq: int = 20,
    extra: dict[str, Any] | None = None,
) -> RobosuiteSpec:
    """The spec of ``env_name`` with one robot under robosuite's default OSC_POSE arm
    controller (the ``BASIC`` composite controller) at ``control_freq`` Hz."""
    kwargs = {"robots": [robot], "control_freq": control_freq, "controller_configs": None}
    kwargs.update(extra or {})
    return RobosuiteSpec(env_name, json.dumps(kwargs, sort_keys=True), tuple(obs_keys))


def spec_from_env_args(env_args: dict[str, Any], obs_keys: Sequence[str]) -> RobosuiteSpec:
    """The spec of a robomimic file's ``env_args`` (rendering settings are dropped)."""
    kwargs = dict(env_args.get("env_kwargs") or {})
    for k in (*_OFF_SCREEN, "camera_names", "camera_heights", "camera_widths", "camera_depths",
              "render_camera", "render_gpu_device_id", "horizon", "renderer"):  # fmt: skip
        kwargs.pop(k, None)
    return RobosuiteSpec(
        str(env_args["env_name"]), json.dumps(kwargs, sort_keys=True), tuple(obs_keys)
    )


def import_robosuite() -> Any:
    """The ``robosuite`` module, with this MuJoCo's compatibility adaptations applied.

    Raises:
      ElicitError: robosuite is not installed.
    """
    try:
        import robosuite
    except ModuleNotFoundError as e:
        raise ElicitError(
            "robosuite tasks need the robosuite extra: pip install -e '.[robosuite]'"
        ) from e
    from elicit_jax.sim.robosuite_compat import ensure_compat

    ensure_compat()
    return robosuite


def _controller_config(suite: Any, given: Any, robot: str) -> Any:
    """robosuite 1.5's composite controller config: the default (``BASIC``: OSC_POSE arm)
    for ``None``, a 1.4-style part config (``{"type": "OSC_POSE", ...}``) converted."""
    from robosuite.controllers import load_composite_controller_config

    if given is None:
        return load_composite_controller_config(controller="BASIC", robot=robot)
    if "body_parts" in given or "body_part_ordering" in given:
        return given
    from robosuite.controllers.composite.composite_controller_factory import (
        refactor_composite_controller_config,
    )

    return refactor_composite_controller_config(given, robot, ["right"])


def make_env(spec: RobosuiteSpec, horizon: int, fast: bool = True) -> Any:
    """A headless robosuite environment of ``spec`` (slow: seconds; build one per process).

    Args:
      spec: the environment and observation keys.
      horizon: robosuite's episode length (callers that count steps pass a large one).
      fast: remember each robot's action size (:func:`remember_action_dims`): the same
        steps, observations and successes, ~6% fewer seconds per step.
    """
    suite = import_robosuite()
    kwargs = spec.env_kwargs
    robots = kwargs.get("robots", "Panda")
    robot = robots[0] if isinstance(robots, list | tuple) else robots
    kwargs["controller_configs"] = _controller_config(
        suite, kwargs.get("controller_configs"), robot
    )
    kwargs.update(_OFF_SCREEN, horizon=int(horizon), reward_shaping=False)
    try:
        env = suite.make(spec.env_name, **kwargs)
    except Exception as e:  # robosuite raises many types for a bad name/argument
        raise ElicitError(f"robosuite cannot build {spec.env_name}: {e}") from e
    if fast:
        remember_action_dims(env)
    return env


def _remembered_action_dim(robot: Any) -> int:
    """A robot's action size, computed once per composite controller (robosuite builds a new
    one at every reset; the size is a function of its configuration only)."""
    controller = robot.composite_controller
    memo = robot.__dict__.get("_elicit_action_dim")
    if memo is None or memo[0] is not controller:
        memo = (controller, int(robot.action_limits[0].shape[0]))
        robot.__dict__["_elicit_action_dim"] = memo
    return memo[1]


def remember_action_dims(env: Any) -> None:
    """Make every robot of ``env`` remember its action size.

    robosuite 1.5 recomputes a robot's ``action_dim`` (concatenating its controllers' action
    limits) three times per physics substep, 25 substeps per control step at 20 Hz: ~7% of a
    step's time (measured: docs/pipelines.md, "Where a robosuite evaluation spends its time").
    The size only changes when the controller does, so each robot's class is swapped for a
    subclass whose ``action_dim`` is computed once per controller; nothing else changes, and
    the steps are the same to the bit (``tests/test_sim_robosuite.py``).
    """
    for robot in env.robots:
        cls = type(robot)
        if getattr(cls, "_elicit_remembers", False):
            continue
        robot.__class__ = type(
            cls.__name__,
            (cls,),
            {
                "action_dim": property(_remembered_action_dim),
                "_elicit_remembers": True,
                "__module__": cls.__module__,
            },
        )


def obs_dims(obs: dict[str, Any]) -> dict[str, int]:
    """Size of every observation the environment offers, under robomimic's key names."""
    dims = {k: int(np.size(v)) for k, v in obs.items()}
    for mimic, suite_key in ROBOMIMIC_KEY_ALIASES.items():
        if suite_key in dims:
            dims[mimic] = dims[suite_key]
    return dims


def flat_obs(obs: dict[str, Any], keys: Sequence[str]) -> np.ndarray:
    """The observation vector: ``keys`` (robomimic names) concatenated in order."""
    parts = [np.ravel(obs[ROBOMIMIC_KEY_ALIASES.get(k, k)]) for k in keys]
    return np.concatenate(parts).astype(np.float64)


def reset_seeded(env: Any, seed: int) -> dict[str, Any]:
    """Reset ``env`` to the initial state of ``seed``; the full observation dict."""
    np.random.seed(int(seed) % (2**32))
    env.reset()
    return env._get_observations(force_update=True)


def success(env: Any) -> bool:
    """robosuite's own success check of the current state."""
    return bool(env._check_success())
