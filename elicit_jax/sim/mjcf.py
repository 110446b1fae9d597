"""MJCF building blocks shared by every task: options, the floating gripper, sensors.

The robot is a floating parallel-jaw gripper. Its base carries four joints in ONE body (slide
x, y, z; hinge z for yaw), each driven by a position actuator, so the kinematic tree stays two
bodies deep (cheap in MJX) while friction still carries a grasped object (the base has real
velocities, unlike a teleported mocap body). The jaw always points down: top-down grasps need
no roll or pitch, and without those joints the end-effector quaternion never drifts off the
yaw axis (a behaviour-cloned policy would otherwise meet roll/pitch values it never saw).
Two slide fingers close symmetrically. The body origin is the end-effector site, centred
between the fingertips.
"""

from __future__ import annotations

FINGER_OPEN = 0.04
"""Finger joint position (m, half the jaw opening) when fully open."""

GRIPPER_JOINTS = ("gx", "gy", "gz", "grz")
FINGER_JOINTS = ("finger_l", "finger_r")


def options(timestep: float) -> str:
    """Simulator options: Euler (implicit joint damping), pyramidal cones, stiff friction."""
    return (
        f'<option timestep="{timestep}" integrator="Euler" cone="pyramidal" impratio="5" '
        'iterations="4" ls_iterations="6"><flag eulerdamp="enable"/></option>'
    )


def defaults() -> str:
    """Default classes: geoms collide only through explicit ``<pair>``s."""
    return """
  <default>
    <geom contype="0" conaffinity="0" condim="3" friction="1 0.005 0.0001" solref="0.01 1"/>
    <joint damping="1" armature="0.01"/>
    <position ctrllimited="true"/>
    <default class="finger">
      <geom type="box" size="0.01 0.005 0.022" rgba="0.2 0.2 0.2 1" mass="0.3"
            friction="1.5 0.005 0.0001"/>
    </default>
  </default>"""


def gripper_body(z_min: float = 0.008) -> str:
    """The floating gripper body (base at the world origin; its joints hold its pose).

    Args:
      z_min: lowest end-effector height allowed (the fingertips stay above the floor).
    """
    o = FINGER_OPEN
    return f"""
    <body name="gripper" gravcomp="1">
      <joint name="gx" type="slide" axis="1 0 0" damping="40" range="-0.5 0.5"/>
      <joint name="gy" type="slide" axis="0 1 0" damping="40" range="-0.5 0.5"/>
      <joint name="gz" type="slide" axis="0 0 1" damping="40" range="{z_min} 0.5"/>
      <joint name="grz" type="hinge" axis="0 0 1" damping="4" range="-3.09 3.09"/>
      <site name="eef" pos="0 0 0" size="0.005" rgba="1 0 0 1"/>
      <geom name="palm" type="box" size="0.012 0.055 0.01" pos="0 0 0.05" mass="0.8"
            rgba="0.3 0.3 0.35 1"/>
      <body name="finger_l" gravcomp="1">
        <joint name="finger_l" type="slide" axis="0 1 0" range="0 {o + 0.005}" damping="2"/>
        <geom name="finger_l" class="finger" pos="0 0.005 0.012"/>
      </body>
      <body name="finger_r" gravcomp="1">
        <joint name="finger_r" type="slide" axis="0 -1 0" range="0 {o + 0.005}" damping="2"/>
        <geom name="finger_r" class="finger" pos="0 -0.005 0.012"/>
      </body>
    </body>"""


def gripper_actuators() -> str:
    """Position servos on the four base joints and the two fingers (force-limited fingers)."""
    lines = []
    for j, kp in (("gx", 400), ("gy", 400), ("gz", 400)):
        lines.append(f'<position name="{j}" joint="{j}" kp="{kp}" ctrlrange="-0.5 0.5"/>')
    lines.append('<position name="grz" joint="grz" kp="40" ctrlrange="-3.09 3.09"/>')
    for j in FINGER_JOINTS:
        lines.append(
            f'<position name="{j}" joint="{j}" kp="300" ctrlrange="0 {FINGER_OPEN}" '
            'forcelimited="true" forcerange="-8 8"/>'
        )
    return "<actuator>\n    " + "\n    ".join(lines) + "\n  </actuator>"


def object_sensors(obj_site: str, more: str) -> str:
    """The sensor block every task's observation starts with, then the task's ``more`` lines.

    ``eef`` position (3) and quaternion (4), finger positions (2), the object site's world
    position (3) and quaternion (4), and its position in the end-effector frame (3): 19
    values.
    """
    return f"""
  <sensor>
    <framepos name="eef_pos" objtype="site" objname="eef"/>
    <framequat name="eef_quat" objtype="site" objname="eef"/>
    <jointpos name="finger_l" joint="finger_l"/>
    <jointpos name="finger_r" joint="finger_r"/>
    <framepos name="obj_pos" objtype="site" objname="{obj_site}"/>
    <framequat name="obj_quat" objtype="site" objname="{obj_site}"/>
    <framepos name="obj_rel_pos" objtype="site" objname="{obj_site}" reftype="site" refname="eef"/>
{more}
  </sensor>"""


def pose_sensors(obj_site: str) -> str:
    """Sensors making up the observation, in order (23 values): :func:`object_sensors` and
    the object's quaternion in the end-effector frame (4)."""
    rel_quat = (
        f'    <framequat name="obj_rel_quat" objtype="site" objname="{obj_site}" reftype="site"\n'
        '               refname="eef"/>'
    )
    return object_sensors(obj_site, rel_quat)


def vertical_capsule(
    name: str, xy: tuple[float, float], top: float, radius: float, rgba: str
) -> str:
    """A fixed capsule standing on the floor at ``xy`` (segment from z = 0 to ``top``)."""
    x, y = xy
    return f"""
    <geom name="{name}" type="capsule" fromto="{x} {y} 0 {x} {y} {top}"
          size="{radius}" rgba="{rgba}"/>"""


def pairs(pairs_: list[tuple[str, str]]) -> str:
    """Explicit contact pairs (the only collisions in a scene), stiff as the timestep allows.

    Pairs with a finger get torsional friction (condim 4), so a grasp resists the object
    swinging about the jaw's closing axis.
    """

    def pair(a: str, b: str) -> str:
        grip = a in FINGER_JOINTS or b in FINGER_JOINTS
        condim, mu, spin = (4, 1.5, 0.06) if grip else (3, 1.0, 0.005)
        return (
            f'<pair geom1="{a}" geom2="{b}" condim="{condim}" solref="0.01 1" '
            f'friction="{mu} {mu} {spin} 0.0001 0.0001"/>'
        )

    body = "\n    ".join(pair(a, b) for a, b in pairs_)
    return f"<contact>\n    {body}\n  </contact>"


def scene(name: str, timestep: float, world: str, contact: str, sensors: str) -> str:
    """A full MJCF document: options, defaults, floor, gripper, ``world`` bodies, sensors.

    The gripper comes first, so its joints are ``qpos[0:6]`` (4 base + 2 fingers) and its
    actuators ``ctrl[0:6]`` in every task.
    """
    return f"""<mujoco model="{name}">
  <compiler angle="radian" autolimits="true"/>
  {options(timestep)}
  {defaults()}
  <worldbody>
    <light pos="0 0 1.5" dir="0 0 -1"/>
    <geom name="floor" type="plane" size="1 1 0.05" rgba="0.85 0.85 0.8 1"/>
    {gripper_body()}
    {world}
  </worldbody>
  {contact}
  {gripper_actuators()}
  {sensors}
</mujoco>"""
