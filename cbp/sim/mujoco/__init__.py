# SPDX-License-Identifier: Apache-2.0
"""MuJoCo beside PyBullet: the scene from a scenario's declarations, the physics.

:mod:`cbp.sim.mujoco.robot_spec` reads the robot's URDF into a MuJoCo spec,
:mod:`cbp.sim.mujoco.scene` adds the scenario's objects and compiles it,
:mod:`cbp.sim.mujoco.physics` drives it under a
:class:`~cbp.sim.simulation.Simulation` (``simulator: mujoco``). Needs the
``mujoco`` extra; submodules are imported on use.
"""
