# SPDX-License-Identifier: Apache-2.0
"""What the robot can collide with: the interface every obstacle source answers.

Both sources, declared objects (:mod:`cbp.collision.objects`) and an occupancy
map (:mod:`cbp.collision.map_environment`), answer one question through
:meth:`Environment.query`: for each robot shape, which obstacle points lie within
a margin, with the signed distance and the normal pointing from the obstacle
toward the robot. Exact distances go through coal, with the obstacle as the first
object, so that the normal convention is the same for shapes and octrees (coal
reports the normal from the first object to the second for shapes, and out of
the occupied cell for octrees).
"""

from __future__ import annotations

import abc
from typing import Literal, NamedTuple

import coal
import numpy as np
import pinocchio as pin

from cbp.collision.contacts import ContactSet
from cbp.collision.convex_kernels import RobotTable
from cbp.collision.geometry import LinkShape, PlacedShapes
from cbp.robot import FloatArray, IntArray

__all__ = ["Environment", "NarrowPhase", "WholeQuery", "signed_distance"]

#: How declared objects and the robot's own shape pairs are measured: in one
#: compiled pass (:mod:`cbp.collision.convex_kernels`) or by coal, called from
#: Python per pair (``collision.narrow_phase``).
NarrowPhase = Literal["compiled", "coal"]


def signed_distance(
    other: coal.CollisionGeometry,
    other_placement: pin.SE3,
    shape: coal.CollisionGeometry,
    placement: pin.SE3,
    request: coal.DistanceRequest,
    result: coal.DistanceResult,
) -> tuple[float, FloatArray, FloatArray, FloatArray]:
    """Signed distance from ``other`` to ``shape`` (coal's GJK/EPA), with witnesses.

    ``other`` goes first, so coal's normal points from it toward ``shape``.

    Returns:
        (distance, point on ``shape``, point on ``other``, unit normal from
        ``other`` toward ``shape``); the distance is negative when they overlap.
    """
    result.clear()
    d = coal.distance(other, other_placement, shape, placement, request, result)
    # The nearest points come back as new arrays; the normal is a view into
    # ``result``, which the next query overwrites.
    return (
        float(d),
        result.getNearestPoint2(),
        result.getNearestPoint1(),
        np.array(result.normal),
    )


class WholeQuery(NamedTuple):
    """The robot's shapes at their frames, asked against the obstacles and each other.

    What :meth:`Environment.query_with_self` measures in one pass.
    """

    frames: FloatArray
    """The shapes' world placements (n, 4, 4)."""
    table: RobotTable
    """The robot's shapes, bounds and self pairs."""
    shapes: list[LinkShape]
    """The shapes themselves."""
    margin: float
    """Obstacles nearer than this to a shape are reported [m] (as
    :meth:`Environment.query`'s)."""
    per_shape: int
    """At most this many obstacle contacts per shape."""
    padding: float
    """Subtracted from the obstacle distances [m]."""
    self_margin: float
    """Self pairs nearer than this are reported [m]."""
    self_padding: float
    """Subtracted from the self pairs' distances [m]."""
    moving: IntArray | None = None
    """The shapes whose obstacle contacts are wanted, by index: a map's
    contacts on the shapes no joint moves (a fixed base on the floor) are
    left out (:meth:`Environment.query_with_self`); None: every shape's."""


class Environment(abc.ABC):
    """A static snapshot of the obstacles; replaced, never modified, when it changes."""

    #: How far the represented surfaces may be from the real ones [m]: 0 for
    #: declared objects, half a cell for an occupancy map. Step validation
    #: tolerates this much more penetration (the links' padding covers it).
    resolution: float = 0.0

    @abc.abstractmethod
    def query(
        self,
        robot: PlacedShapes,
        margin: float,
        per_shape: int,
        narrow_phase: NarrowPhase = "compiled",
    ) -> ContactSet:
        """Contacts of each robot shape with obstacles closer than ``margin``.

        Args:
            robot: the robot's shapes placed in the world, with their bounds.
            margin: report obstacles whose distance to a shape is below this [m].
            per_shape: at most this many contacts per shape (the closest, spread
                over distinct directions).
            narrow_phase: how exact distances to declared shapes are measured
                (``collision.narrow_phase``); an environment that measures
                otherwise (an occupancy map's cells) ignores it.

        Returns:
            Obstacle contacts (``other_shape`` -1), with the distances of the
            unpadded shapes.
        """

    def query_with_self(self, whole: WholeQuery) -> ContactSet | None:
        """The whole contact query in one compiled pass, if this environment can.

        Obstacle contacts (as :meth:`query` with the compiled narrow phase,
        distances less ``whole.padding``) and the self contacts of the table's
        pairs within ``whole.self_margin`` (distances less
        ``whole.self_padding``), stacked as :meth:`ContactSet.stack` does;
        with ``whole.moving``, obstacle contacts on those shapes only.
        None (the default): the world queries the environment and the self
        pairs apart.
        """
        del whole
        return None

    def prepare(self, shapes: list[LinkShape], margin: float) -> None:
        """Get ready for queries of ``shapes`` up to ``margin``: build, compile.

        Called when a world takes this snapshot, in the thread that hands it over
        (the map thread), so that the control loop's first query pays nothing
        extra. Nothing to do by default.
        """
        del shapes, margin

    @abc.abstractmethod
    def collision_objects(self) -> list[tuple[str, coal.CollisionGeometry, pin.SE3]]:
        """The obstacles as coal geometries: (name, shape, world placement).

        For yes-or-no checks (:class:`~cbp.collision.checker.FreeSpaceChecker`).
        """

    def allowed_contacts(self) -> list[frozenset[str]]:
        """Per collision object, the robot links that may touch it (none here)."""
        return [frozenset()] * len(self.collision_objects())

    #: True when :meth:`collision_objects` holds only the obstacles' surfaces
    #: (a map's shell of cells next to open space): a shape wholly inside an
    #: obstacle then touches none of them, and checks ask :meth:`inside` too.
    surfaces_only: bool = False

    @abc.abstractmethod
    def clearance(self, points: FloatArray) -> FloatArray:
        """Distance from each point (n, 3) to the nearest obstacle [m].

        For tests and plots; not used in the control loop.
        """

    def inside(self, points: FloatArray) -> np.ndarray:
        """Which points (n, 3) lie in an obstacle (boolean (n,))."""
        return np.asarray(self.clearance(points) <= 0.0)
