"""Simulation: MJX/MuJoCo manipulation tasks, scripted operators, collection and evaluation.

Modules: :mod:`.env` (env state, task base class, registry), :mod:`.mjcf` (the floating
gripper and scene builder), :mod:`.tasks` (``reach-pillar``, ``square-nut``, ``round-nut``),
:mod:`.operators` (scripted operator styles), :mod:`.collect`, :mod:`.rollout_mujoco` (C
MuJoCo batch), :mod:`.rollout_mjx` (jitted MJX rollouts), :mod:`.evaluate`.
"""
