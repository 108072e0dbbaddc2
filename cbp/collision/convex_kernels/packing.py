# SPDX-License-Identifier: Apache-2.0
"""Convex shapes packed in flat arrays for the compiled narrow phase.

Each shape is a *core* grown by a radius (:mod:`cbp.collision.convex_kernels`):
:func:`pack_shapes` writes coal shapes' kinds, sizes, radii and hulls'
vertices with their edges' neighbours into a :class:`ConvexShapes`; the
kernels take its arrays as a plain tuple (:data:`Table`, :func:`fields`). A
robot's shapes are packed once and kept (:func:`packed_robot`), with their
bounds and self pairs (:class:`RobotTable`).
"""

from __future__ import annotations

import functools
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING

import coal
import numpy as np
import numpy.typing as npt

from cbp.robot import FloatArray, IntArray

if TYPE_CHECKING:
    from cbp.collision.geometry import LinkShape

__all__ = [
    "BOX",
    "CAPSULE",
    "CONVEX",
    "CYLINDER",
    "SPHERE",
    "UNSUPPORTED",
    "ConvexShapes",
    "LocalBounds",
    "RobotTable",
    "SelfPairs",
    "Table",
    "fields",
    "pack_shapes",
    "packed_robot",
]

#: Kinds of :attr:`ConvexShapes.kind`.
CONVEX, BOX, SPHERE, CAPSULE, CYLINDER = 0, 1, 2, 3, 4
#: A shape the kernels do not measure (a non-convex mesh, an octree): coal does.
UNSUPPORTED = -1


@dataclass(frozen=True)
class ConvexShapes:
    """Convex shapes packed for the kernels.

    Attributes:
        kind: :data:`CONVEX`, :data:`BOX`, :data:`SPHERE`, :data:`CAPSULE`,
            :data:`CYLINDER` or :data:`UNSUPPORTED`, (n,).
        size: box half sides; (radius, half length, 0) of cylinders and
            capsules; zeros otherwise (n, 3) [m].
        radius: the core's growth: a sphere's or capsule's radius plus the
            shape's swept-sphere radius (n,) [m].
        vertex_start: hull s's vertices are rows ``vertex_start[s]`` to
            ``vertex_start[s + 1]`` of ``vertices``, (n + 1,).
        vertices: every hull's vertices in its own frame, stacked (V, 3) [m].
        neighbor_start: vertex v's neighbours (along the hull's edges) are
            ``neighbors[neighbor_start[v]:neighbor_start[v + 1]]``, (V + 1,).
        neighbors: the neighbours' rows in ``vertices``, stacked.
    """

    kind: npt.NDArray[np.int64]
    size: FloatArray
    radius: FloatArray
    vertex_start: npt.NDArray[np.int64]
    vertices: FloatArray
    neighbor_start: npt.NDArray[np.int64]
    neighbors: npt.NDArray[np.int64]

    @property
    def supported(self) -> bool:
        """Whether the kernels measure every shape."""
        return bool(np.all(self.kind != UNSUPPORTED))


@dataclass(frozen=True)
class RobotTable:
    """A robot's shapes as the contact queries read them.

    :func:`~cbp.collision.convex_kernels.declared_contacts` and
    :func:`~cbp.collision.convex_kernels.self_overlap` take its bounds and pairs.

    Attributes:
        centres: bounding-sphere centres in the shapes' own frames (n, 3) [m].
        halves: bounding-box half extents about them, same frames (n, 3) [m].
        radii: bounding-sphere radii (n,) [m].
        shapes: the packed shapes.
        first: the self pairs' first shapes (none: no self-collision), (P,).
        second: their second shapes (P,).
        self_guess: where the self pairs' next GJK starts (P, 5), updated by
            each query (:func:`~cbp.collision.convex_kernels.pair_distance`).
    """

    centres: FloatArray
    halves: FloatArray
    radii: FloatArray
    shapes: ConvexShapes
    first: IntArray
    second: IntArray
    self_guess: FloatArray

    @functools.cached_property
    def bounds(self) -> LocalBounds:
        """Bounds and packed shapes as the queries take them (:data:`LocalBounds`)."""
        return (self.centres, self.halves, self.radii, fields(self.shapes))

    def pairs(self, margin: float, padding: float) -> SelfPairs:
        """The self pairs as the queries take them (:data:`SelfPairs`)."""
        return (self.first, self.second, self.self_guess, margin, padding)


#: A packed table's arrays, in :func:`fields`' order, as the kernels take them.
Table = tuple[
    IntArray, FloatArray, FloatArray, IntArray, FloatArray, IntArray, IntArray
]
#: A robot's shapes as
#: :func:`~cbp.collision.convex_kernels.declared_contacts` takes them
#: (:attr:`RobotTable.bounds`): the bounds in the shapes' own frames (centres,
#: halves, radii) and the packed :data:`Table`.
LocalBounds = tuple[FloatArray, FloatArray, FloatArray, Table]
#: A robot's self pairs as the kernels take them: ``first``, ``second`` (P,),
#: each pair's GJK start ``self_guess`` (P, 5), the margin and the padding
#: taken off the distances [m].
SelfPairs = tuple[IntArray, IntArray, FloatArray, float, float]


def pack_shapes(shapes: list[coal.CollisionGeometry]) -> ConvexShapes:
    """Pack coal shapes; those the kernels do not measure are :data:`UNSUPPORTED`."""
    n = len(shapes)
    kind = np.full(n, UNSUPPORTED, dtype=np.int64)
    size = np.zeros((n, 3))
    radius = np.zeros(n)
    start = [0]
    vertices = []
    adjacent: list[list[int]] = []
    for s, shape in enumerate(shapes):
        if isinstance(shape, coal.Convex):
            points = np.asarray(shape.points(), dtype=float).reshape(-1, 3)
            kind[s] = CONVEX
            vertices.append(points)
            adjacent += _neighbours(shape, start[-1])
        elif isinstance(shape, coal.Box):
            kind[s] = BOX
            size[s] = np.asarray(shape.halfSide, dtype=float)
        elif isinstance(shape, coal.Sphere):
            kind[s] = SPHERE
            radius[s] = float(shape.radius)
        elif isinstance(shape, coal.Capsule):
            kind[s] = CAPSULE
            size[s] = float(shape.radius), float(shape.halfLength), 0.0
            radius[s] = float(shape.radius)
        elif isinstance(shape, coal.Cylinder):
            kind[s] = CYLINDER
            size[s] = float(shape.radius), float(shape.halfLength), 0.0
        if kind[s] != UNSUPPORTED:
            radius[s] += float(shape.getSweptSphereRadius())
        start.append(start[-1] + (len(vertices[-1]) if kind[s] == CONVEX else 0))
    counts = [len(a) for a in adjacent]
    return ConvexShapes(
        kind=kind,
        size=size,
        radius=radius,
        vertex_start=np.array(start, dtype=np.int64),
        vertices=np.ascontiguousarray(
            np.concatenate(vertices) if vertices else np.zeros((0, 3))
        ),
        neighbor_start=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        neighbors=np.array([v for a in adjacent for v in a], dtype=np.int64),
    )


def _neighbours(shape: coal.Convex, offset: int) -> list[list[int]]:
    """Each vertex's neighbours along the hull's triangles (rows from ``offset``)."""
    count = int(shape.num_points)
    adjacent: list[set[int]] = [set() for _ in range(count)]
    for f in range(int(shape.num_polygons)):
        polygon = shape.polygons(f)
        corners = [int(polygon[k]) for k in range(polygon.size())]
        for k, a in enumerate(corners):
            b = corners[(k + 1) % len(corners)]
            adjacent[a].add(b)
            adjacent[b].add(a)
    return [sorted(offset + b for b in a) for a in adjacent]


def fields(shapes: ConvexShapes) -> Table:
    """The arrays in the kernels' order (a :data:`Table`)."""
    return (
        shapes.kind,
        shapes.size,
        shapes.radius,
        shapes.vertex_start,
        shapes.vertices,
        shapes.neighbor_start,
        shapes.neighbors,
    )


#: Packed robot shapes by the shapes' identities, with the shapes they are for.
_ROBOTS: dict[tuple[int, ...], tuple[list[LinkShape], ConvexShapes]] = {}
_ROBOT_CACHE = 8
_CACHE_LOCK = threading.Lock()


def packed_robot(shapes: list[LinkShape]) -> ConvexShapes:
    """:func:`pack_shapes` of a robot's shapes, packed once and kept.

    A few are kept, with their shapes (so the key, the shapes' identities,
    cannot be reused by other objects while they are kept).
    """
    key = tuple(id(shape) for shape in shapes)
    found = _ROBOTS.get(key)
    if found is None:
        found = (list(shapes), pack_shapes([s.shape for s in shapes]))
        with _CACHE_LOCK:  # the map thread and the control loop both look
            if len(_ROBOTS) >= _ROBOT_CACHE:
                _ROBOTS.pop(next(iter(_ROBOTS)))
            _ROBOTS[key] = found
    return found[1]
