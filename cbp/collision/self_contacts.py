# SPDX-License-Identifier: Apache-2.0
"""The contacts between the robot's own shapes, measured apart from the obstacles.

A world's query measures the self pairs in the same compiled pass as the
obstacles when its environment can
(:meth:`~cbp.collision.environment.Environment.query_with_self`); otherwise,
and for the robot alone, they are measured here: every pair the broad phase
keeps in one compiled call (each from its last normal), or by coal called per
pair (``collision.narrow_phase: coal``, and the pairs the kernels cannot
measure). Distances are those of the padded shapes.
"""

from __future__ import annotations

import coal
import numpy as np

from cbp.collision.contacts import ContactRow, ContactSet
from cbp.collision.convex_kernels import placed_robot, self_contacts
from cbp.collision.environment import signed_distance
from cbp.collision.geometry import PlacedShapes, RobotGeometry
from cbp.collision.settings import CollisionSettings
from cbp.robot import IntArray

__all__ = ["SelfContacts"]


class SelfContacts:
    """The contacts between a robot's own shape pairs (padded distances).

    Args:
        geometry: the robot's shapes and self pairs.
        settings: the narrow phase and the activation distance.
        padding: distance added around every shape [m].

    Not thread-safe: it keeps each pair's GJK start and coal's buffers.
    """

    def __init__(
        self, geometry: RobotGeometry, settings: CollisionSettings, padding: float
    ) -> None:
        """Keep the parts, with a GJK start per self pair."""
        self.geometry = geometry
        self.settings = settings
        self.padding = padding
        self._request = coal.DistanceRequest()
        self._result = coal.DistanceResult()
        #: Where each self pair's GJK starts next.
        self._guess = np.zeros((len(geometry.self_pairs), 5))

    def contacts(self, robot: PlacedShapes) -> ContactSet:
        """The contacts between the robot's own shapes at ``robot``'s placements.

        Args:
            robot: the shapes at a configuration
                (:meth:`~cbp.collision.world.CollisionWorld.placed`).
        """
        own = self.measured(robot)
        return own if isinstance(own, ContactSet) else ContactSet.from_rows(own)

    def measured(self, robot: PlacedShapes) -> ContactSet | list[ContactRow]:
        """:meth:`contacts` as the narrow phase gives them, for stacking.

        Compiled (``collision.narrow_phase: compiled``): a set measured in one
        pass; with coal: rows (:meth:`rows`).
        """
        if self.settings.narrow_phase == "coal":
            return self.rows(robot)
        geometry = self.geometry
        first, second = geometry.pair_arrays
        guess = self._guess
        n = len(first)
        if not n:
            return ContactSet.empty()
        pad2 = 2.0 * self.padding
        index = np.empty((2, n), dtype=np.intp)
        floats = np.empty((4, n, 3))
        left = np.empty((2, n), dtype=np.intp)
        count, missed = self_contacts(
            placed_robot(robot),
            (first, second, guess, self.settings.activation_distance + pad2, pad2),
            index,
            floats,
            left,
        )
        found = ContactSet.packed(index, floats, 0, count)
        if not missed:
            return found
        return ContactSet.concatenate(
            [found, ContactSet.from_rows(self.rows(robot, left[1, :missed]))]
        )

    def rows(
        self, robot: PlacedShapes, which: IntArray | None = None
    ) -> list[ContactRow]:
        """:meth:`contacts` measured by coal, as rows, to stack in one call.

        Args:
            robot: the shapes at a configuration.
            which: the indices into :attr:`RobotGeometry.self_pairs` to measure
                (default: those the broad phase keeps).
        """
        shapes = self.geometry.shapes
        placements, centres, halves = robot.placements, robot.centres, robot.halves
        pad2 = 2.0 * self.padding
        margin = self.settings.activation_distance + pad2
        rows = []
        request, result = self._request, self._result
        pairs = self.geometry.self_pairs
        near = (
            self.geometry.near_self_pairs(centres, margin, halves)
            if which is None
            else which.tolist()
        )
        for k in near:
            i, j = pairs[k]
            # Shape j first: the normal then points from j toward i.
            d, point, other, normal = signed_distance(
                shapes[j].shape,
                placements[j],
                shapes[i].shape,
                placements[i],
                request,
                result,
            )
            if d < margin:
                rows.append((i, j, point, other, normal, d - pad2))
        return rows
