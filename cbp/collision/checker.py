# SPDX-License-Identifier: Apache-2.0
"""Yes-or-no collision checks for planners and IK, in one pinocchio call.

A sampling planner asks thousands of times per plan whether a configuration is free,
and needs no contacts, normals or distances. :class:`FreeSpaceChecker` answers in
C++ from end to end: pinocchio's forward kinematics and geometry placements, coal's
dynamic AABB tree as broad phase, and coal's narrow phase, stopping at the first
collision.

The robot's shapes are copies grown by the padding (coal's swept-sphere radius,
which also grows their bounding boxes, so the broad phase misses nothing within
the padding). A configuration is free when no padded shape overlaps an obstacle
(grown by the environment's resolution) deeper than ``tolerance``, and no two
padded shapes of a checked pair overlap: with ``tolerance`` 0, exactly when
``CollisionWorld.check(q).penetration`` is 0.
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin

from cbp.collision.environment import Environment
from cbp.collision.geometry import RobotGeometry
from cbp.robot import FloatArray

__all__ = ["FreeSpaceChecker"]


class FreeSpaceChecker:
    """Whether configurations are collision-free, against one environment snapshot.

    Args:
        geometry: the robot's shapes and self-collision pairs.
        environment: the obstacles (its :meth:`Environment.collision_objects`).
        padding: distance added around every robot shape [m].
        self_collision: also check the robot's own shape pairs.
        tolerance: how deep a padded shape may reach into an obstacle (grown
            by the environment's resolution) and still be free [m] (CAT's
            step validation accepts its penetration tolerance plus the
            resolution).

    Not thread-safe: each thread needs its own checker (they are cheap to build).
    """

    def __init__(
        self,
        geometry: RobotGeometry,
        environment: Environment,
        padding: float,
        self_collision: bool = True,
        tolerance: float = 0.0,
    ) -> None:
        """Build the pinocchio geometry model, its pairs and the broad phase."""
        self.environment = environment
        robot = geometry.robot
        self._model = robot.model
        self._data = robot.model.createData()
        # Occupancy maps represent surfaces to half a cell: obstacle pairs collide
        # that much earlier, as in the contact queries, and ``tolerance`` later.
        # Coal takes that as a security margin on the pair, but not a negative
        # one against an octree: a tolerance beyond the half cell shrinks the
        # shapes' padding instead, and self pairs get it back as their margin.
        margin = environment.resolution - tolerance
        shrink = min(max(0.0, -margin), padding)
        geometry_model = geometry.geometry_model(padding - shrink)
        n = len(geometry.shapes)
        obstacles = environment.collision_objects()
        for name, obstacle, placement in obstacles:
            geometry_model.addGeometryObject(
                pin.GeometryObject(f"environment/{name}", 0, 0, placement, obstacle)
            )
        allowed = environment.allowed_contacts()
        for i in range(n):
            link = geometry.shapes[i].link
            for k in range(len(obstacles)):
                if link not in allowed[k]:  # wanted contact is not checked
                    geometry_model.addCollisionPair(pin.CollisionPair(i, n + k))
        if self_collision:
            for i, j in geometry.self_pairs:
                geometry_model.addCollisionPair(pin.CollisionPair(i, j))
        self._geometry_model = geometry_model
        self._geometry_data = pin.GeometryData(geometry_model)
        for k, pair in enumerate(geometry_model.collisionPairs):
            request: coal.CollisionRequest = self._geometry_data.collisionRequests[k]
            request.security_margin = (
                max(0.0, margin + shrink) if pair.second >= n else 2.0 * shrink
            )
        self._manager = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(
            self._model, geometry_model, self._geometry_data
        )
        self._has_pairs = len(geometry_model.collisionPairs) > 0
        # A map's octree holds only the shell of its obstacle cells: a shape
        # that touches no shell cell is free unless it lies wholly inside (its
        # centre in an obstacle cell), which the map's grid tells.
        self._interior = environment.surfaces_only
        self._centres = [s.placement.actInv(s.centre) for s in geometry.shapes]

    def is_free(self, q: FloatArray) -> bool:
        """True when no checked pair of padded shapes overlaps at ``q``."""
        if not self._has_pairs:
            return True
        q = np.asarray(q, dtype=float)
        if pin.computeCollisions(self._model, self._data, self._manager, q, True):
            return False
        if not self._interior:
            return True
        oMg = self._geometry_data.oMg  # placed by computeCollisions
        points = np.array([oMg[i].act(c) for i, c in enumerate(self._centres)])
        return not bool(self.environment.inside(points).any())

    def __repr__(self) -> str:
        """Shape and pair counts."""
        return (
            f"FreeSpaceChecker(geometries={self._geometry_model.ngeoms}, "
            f"pairs={len(self._geometry_model.collisionPairs)})"
        )
