"""``robosuite-square`` and ``robosuite-round``: the paper's own environments.

robosuite's ``NutAssemblySquare`` / ``NutAssemblyRound`` with one Panda arm under the
OSC_POSE controller at 20 Hz, observed through robomimic's low-dimensional keys
(``robot0_eef_pos`` 3, ``robot0_eef_quat`` 4 (x-y-z-w, robosuite's order),
``robot0_gripper_qpos`` 2, ``object`` 14: 23 values, the layout of the MuJoCo analogues).
Actions: robosuite's 7 values in [-1, 1] (delta position up to 5 cm per step, delta rotation
up to 0.5 rad as a world-frame axis-angle, gripper -1 open / +1 closed). Success is
robosuite's own check. These tasks run on the robosuite backend only (worker processes,
one environment each: :mod:`elicit_jax.sim.rollout_robosuite`); a session (``elicit``,
``serve``) steps one environment in its own process (:mod:`elicit_jax.sim.single`).
Constructing the task does not import robosuite, building an environment does (so does
reading :attr:`RobosuiteTask.mj_model`).

The browser draws the scene from the environment's MuJoCo model (:attr:`scene_hints`, read by
:mod:`elicit_jax.web.scene`): the table top is moved to height 0, where the page's camera,
grid and top view look; the arm and gripper are drawn from their collision shapes, one mesh
per link, each as the box bounding it (the page draws primitives only); robosuite's textured
materials are drawn in the plain colours given here.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar

from elicit_jax.data.demos import ObsField
from elicit_jax.errors import ElicitError
from elicit_jax.sim.env import OBS_FIELDS, Task, TaskConfig
from elicit_jax.sim.robosuite_env import RobosuiteSpec, spec_for

OBS_KEYS = tuple(f.name for f in OBS_FIELDS)


@dataclasses.dataclass(frozen=True)
class RobosuiteConfig(TaskConfig):
    """A robosuite task's settings.

    Attributes:
      robot: robosuite robot name.
      control_freq: control steps per second.
      pos_scale, rot_scale: the OSC_POSE controller's largest delta per control step (m,
        rad), for the scripted operators' gains.
    """

    robot: str = "Panda"
    control_freq: int = 20
    pos_scale: float = 0.05
    rot_scale: float = 0.5


class RobosuiteTask(Task):
    """A task played in a robosuite environment (no MJCF of ours, no MJX)."""

    backend: ClassVar[str] = "robosuite"
    env_name: ClassVar[str] = ""
    peg_xy: ClassVar[tuple[float, float]] = (0.0, 0.0)
    handle_offset: ClassVar[float] = 0.0
    """Handle's grasp point from the nut's centre, along the nut's x axis (robosuite's
    ``handle_site``)."""
    peg_symmetry: ClassVar[float] = 0.0
    """Turn (rad) after which the peg looks the same (0: round, any yaw fits)."""

    scene_hints: ClassVar[dict[str, Any]] = {
        "origin": (0.0, 0.0, 0.82),
        "home": {"position": (0.0, -1.3, 0.7), "target": (-0.05, 0.0, 0.1)},
        "meshes": "collision-boxes",
        "gripper": "gripper0_right_eef",
        "colours": {
            "table": (0.72, 0.6, 0.45, 1.0),
            "peg": (0.45, 0.45, 0.5, 1.0),
            "SquareNut": (0.85, 0.65, 0.2, 1.0),
            "RoundNut": (0.85, 0.65, 0.2, 1.0),
            "robot0": (0.92, 0.92, 0.92, 1.0),
            "gripper0": (0.3, 0.3, 0.32, 1.0),
            "fixed_mount0": (0.25, 0.25, 0.25, 1.0),
            "floor": (0.82, 0.82, 0.8, 1.0),
            "wall": (0.93, 0.93, 0.92, 1.0),
        },
    }
    """How the browser draws this task (see the module docstring): the world point drawn
    at the origin, the camera's home, meshes as their collision shapes' bounding boxes, the
    body the gripper's trail follows, colours by body (or world geom) name prefix."""

    def __init__(self, config: TaskConfig | None = None) -> None:
        self.config = config or self.config_cls()

    @property
    def mj_model(self) -> Any:
        """The MuJoCo model of this task's robosuite environment (builds one in this process
        on first use: seconds)."""
        from elicit_jax.sim.single import robosuite_model

        return robosuite_model(self.spec)

    @property
    def obs_fields(self) -> tuple[ObsField, ...]:
        return OBS_FIELDS

    @property
    def spec(self) -> RobosuiteSpec:
        """The environment (robomimic ``env_args``) and observation keys of this task."""
        c = self.config
        return spec_for(self.env_name, OBS_KEYS, c.robot, c.control_freq)  # type: ignore[attr-defined]

    def sample_init(self, rng: Any) -> tuple[Any, Any]:
        raise ElicitError(f"task '{self.name}' runs on robosuite: its initial states are seeds")

    def success_from_obs(self, obs: Any, xp: Any = None) -> Any:
        raise ElicitError(f"task '{self.name}': success is robosuite's own check")


class RobosuiteSquare(RobosuiteTask):
    """robosuite NutAssemblySquare (robomimic's Square)."""

    name = "robosuite-square"
    config_cls = dataclasses.make_dataclass(
        "SquareConfig", [("horizon", int, 500)], bases=(RobosuiteConfig,), frozen=True
    )
    env_name = "NutAssemblySquare"
    peg_xy = (0.23, 0.1)
    handle_offset = 0.054
    peg_symmetry = math.pi / 2


class RobosuiteRound(RobosuiteTask):
    """robosuite NutAssemblyRound."""

    name = "robosuite-round"
    config_cls = dataclasses.make_dataclass(
        "RoundConfig", [("horizon", int, 400)], bases=(RobosuiteConfig,), frozen=True
    )
    env_name = "NutAssemblyRound"
    peg_xy = (0.23, -0.1)
    handle_offset = 0.06
