# SPDX-License-Identifier: Apache-2.0
"""MuJoCo beside PyBullet: the scene from a scenario's declarations, the physics.

:mod:`cbp.sim.mujoco.robot_spec` reads the robot's URDF into a MuJoCo spec,
:mod:`cbp.sim.mujoco.scene` adds the scenario's objects and compiles it,
:mod:`cbp.sim.mujoco.physics` drives it under a
:class:`~cbp.sim.simulation.Simulation` (``simulator: mujoco``) and
:mod:`cbp.sim.mujoco.camera` renders its depth cameras. Needs the ``mujoco``
extra; submodules are imported on use.

MuJoCo chooses its OpenGL back end when it is first imported: this package
asks for EGL (``MUJOCO_GL=egl``; Mesa renders without a GPU or a display)
unless the environment names another, before any of its modules imports
``mujoco``.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
