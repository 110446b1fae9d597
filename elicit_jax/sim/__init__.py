"""Simulation: MJX/MuJoCo manipulation tasks, scripted operators, collection and evaluation.

Modules: :mod:`.registry` (one entry per task: its class, scripted operators and threshold
preset), :mod:`.env` (env state, task base class, ``make_task``), :mod:`.mjcf` (the floating
gripper and scene builder), :mod:`.tasks` (one task class per module), :mod:`.operators`
(scripted operator styles), :mod:`.collect`, :mod:`.rollout_mujoco` (C MuJoCo batch),
:mod:`.rollout_mjx` (jitted MJX rollouts), :mod:`.evaluate`, :mod:`.single` (one environment
of any task in this process: sessions, replays, the browser's scene); the robosuite backend
(optional extra): :mod:`.robosuite_env` (one environment), :mod:`.robosuite_compat` (MuJoCo
3.17 adaptations), :mod:`.rollout_robosuite` (worker processes), :mod:`.evaluate_robosuite`.
"""
