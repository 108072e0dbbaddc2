# SPDX-License-Identifier: Apache-2.0
"""MuJoCo beside PyBullet: the scene, its physics and its cameras.

MuJoCo chooses its OpenGL back end when it is first imported: this package
asks for EGL (``MUJOCO_GL=egl``; Mesa renders without a GPU or a display)
unless the environment names another, so every module here imports ``mujoco``
after this line has run.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
