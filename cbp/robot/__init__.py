# SPDX-License-Identifier: Apache-2.0
"""Robot models: a URDF loaded through pinocchio, with names resolved to indices.

Configurations ``q`` have ``nq`` entries; velocities and displacements live in the
tangent space and have ``nv`` entries. The two differ for continuous joints (cos, sin),
planar bases (x, y, cos, sin) and floating bases (position + quaternion), which is why
every change of configuration goes through :meth:`RobotModel.integrate` and
:meth:`RobotModel.difference`.

:class:`RobotModel` is in :mod:`cbp.robot.model`; a robot folder's
``robot.yaml`` and where folders are found in :mod:`cbp.robot.description`;
loading and checking them in :mod:`cbp.robot.loading`; what a model's joints
say (limits, units, the support) in :mod:`cbp.robot.joints`.
"""

from cbp.robot.arrays import FloatArray, IndexRows, IntArray, compact_rows, rows_count
from cbp.robot.description import (
    ROBOTS_DIR,
    Approximation,
    BaseType,
    CollisionDescription,
    RobotDescription,
    find_robot_folder,
)
from cbp.robot.model import LIMIT_TOLERANCE, RobotModel

__all__ = [
    "LIMIT_TOLERANCE",
    "ROBOTS_DIR",
    "Approximation",
    "BaseType",
    "CollisionDescription",
    "FloatArray",
    "IndexRows",
    "IntArray",
    "RobotDescription",
    "RobotModel",
    "compact_rows",
    "find_robot_folder",
    "rows_count",
]
