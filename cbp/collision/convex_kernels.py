# SPDX-License-Identifier: Apache-2.0
"""Signed distances between convex shapes, compiled: GJK, then EPA where they overlap.

The contact queries against declared objects and between the robot's own shapes
measure each pair the broad phase keeps (:mod:`cbp.collision.broad`). Called
from Python, coal takes 3-5 us per pair plus the call's own cost; here one
compiled pass measures every pair and writes the contacts to flat arrays.

Each shape is a *core* grown by a radius: a convex hull (its vertices), a box
or a cylinder with radius 0, a sphere (a point) or a capsule (a segment) with
their radius (and any of them with coal's swept-sphere radius added). The
distance of two shapes is the distance of their cores less both radii, exact
for spheres and capsules, with the witness points moved along the normal.

- **GJK** (Gilbert, Johnson and Keerthi) finds the point of the cores'
  Minkowski difference A - B nearest the origin, the closest point of the
  current simplex by its Voronoi regions. It stops when a support point no
  longer brings the bound down by more than ``GJK_TOLERANCE`` [m]: for
  polytopes (hulls, boxes) that is the exact answer; for a cylinder's rim the
  distance is within that tolerance.
- **EPA** (expanding polytope) measures the penetration when the cores overlap:
  a polytope inside A - B, grown by the support point beyond its face nearest
  the origin until that face is on the boundary (within ``EPA_TOLERANCE``).
  For polytopes it is the exact penetration depth.

Results follow coal's convention (:func:`cbp.collision.environment.signed_distance`,
the obstacle or other shape B first): the normal points from B toward A, the
distance is negative when they overlap, and ``point_a - point_b = distance *
normal``. Where the shapes touch along a face, the witness points are one pair
of the many; the distance and normal are unique for separated shapes.

A hull's support point is found by climbing its edges from the last one (a
few dot products instead of one per vertex), and each pair's GJK starts from
its last normal and support vertices (``guess``): between two control steps
the shapes move little, and a pair takes a few iterations. A guess is only a
starting point: the distance and normal do not depend on it (to GJK's
tolerance), so two threads that query the same environment at once (each
writing its guesses) change how many iterations a pair takes, not the
contacts.

Shapes are packed in flat arrays (:class:`ConvexShapes`), which the kernels
take grouped in plain tuples (:data:`Table`, :data:`Placed`, :data:`Obstacles`,
:data:`SelfPairs`): numba types a plain tuple of arrays in its compiled
dispatcher (about 0.1 us for a whole query's arguments, as for the arrays one
by one), a named tuple in Python (about 0.5 us for each of them). Inside the
kernels, one shape where it stands is a :class:`PlacedConvex`, and one
function gives the support point of A - B for GJK and EPA alike.
"""

from __future__ import annotations

import functools
import math
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import coal
import numba
import numpy as np
import numpy.typing as npt

from cbp.collision.broad import near_objects, near_pairs, shape_bounds
from cbp.robot import FloatArray, IntArray

if TYPE_CHECKING:
    from cbp.collision.geometry import LinkShape, PlacedShapes

__all__ = [
    "BOX",
    "CAPSULE",
    "CONVEX",
    "CYLINDER",
    "EPA_TOLERANCE",
    "FAILED",
    "GJK_TOLERANCE",
    "SPHERE",
    "UNSUPPORTED",
    "ConvexShapes",
    "LocalBounds",
    "Obstacles",
    "Placed",
    "PlacedConvex",
    "RobotTable",
    "SelfPairs",
    "Table",
    "compile_convex_kernels",
    "contact_buffers",
    "declared_contacts",
    "fields",
    "obstacle_contacts",
    "pack_shapes",
    "packed_robot",
    "pair_distance",
    "placed_robot",
    "self_contacts",
    "self_overlap",
]

#: Kinds of :attr:`ConvexShapes.kind`.
CONVEX, BOX, SPHERE, CAPSULE, CYLINDER = 0, 1, 2, 3, 4
#: A shape the kernels do not measure (a non-convex mesh, an octree): coal does.
UNSUPPORTED = -1
#: Status of a pair that the kernels could not measure (a degenerate EPA start).
FAILED = 1
#: GJK stops when a support point improves the distance bound by less [m].
GJK_TOLERANCE = 1e-10
#: EPA stops when the face nearest the origin is this close to the boundary [m].
EPA_TOLERANCE = 1e-10
_GJK_ITERATIONS = 128
_EPA_VERTICES = 128
_EPA_FACES = 4 * _EPA_VERTICES
_EPA_EDGES = 3 * _EPA_FACES


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
    """A robot's shapes as :func:`declared_contacts` reads them.

    Attributes:
        centres: bounding-sphere centres in the shapes' own frames (n, 3) [m].
        halves: bounding-box half extents about them, same frames (n, 3) [m].
        radii: bounding-sphere radii (n,) [m].
        shapes: the packed shapes.
        first: the self pairs' first shapes (none: no self-collision), (P,).
        second: their second shapes (P,).
        self_guess: where the self pairs' next GJK starts (P, 5), updated by
            each query (:func:`pair_distance`).
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
        """Bounds and packed shapes as :func:`declared_contacts` takes them."""
        return (self.centres, self.halves, self.radii, fields(self.shapes))

    def pairs(self, margin: float, padding: float) -> SelfPairs:
        """The self pairs as :func:`declared_contacts` takes them."""
        return (self.first, self.second, self.self_guess, margin, padding)


class PlacedConvex(NamedTuple):
    """One packed shape at its world placement, as :func:`pair_distance` reads it.

    Attributes:
        kind: :data:`CONVEX`, ... (:attr:`ConvexShapes.kind`).
        size: its size (:attr:`ConvexShapes.size`) (3,) [m].
        radius: its core's growth [m].
        vertices: the vertices of its table (a hull's are rows
            ``start:stop``).
        start: its first vertex.
        stop: past its last.
        neighbor_start: its table's :attr:`ConvexShapes.neighbor_start`.
        neighbors: its table's :attr:`ConvexShapes.neighbors`.
        frame: its world placement (4, 4).
    """

    kind: int
    size: FloatArray
    radius: float
    vertices: FloatArray
    start: int
    stop: int
    neighbor_start: IntArray
    neighbors: IntArray
    frame: FloatArray


#: A packed table's arrays, in :func:`fields`' order, as the kernels take them.
Table = tuple[
    IntArray, FloatArray, FloatArray, IntArray, FloatArray, IntArray, IntArray
]
#: A placed robot as the kernels take it (:func:`placed_robot`): its shapes'
#: bounds in the world (centres (n, 3), box half extents (n, 3), sphere radii
#: (n,), :mod:`cbp.collision.broad`'s), their placements (n, 4, 4) and their
#: packed :data:`Table`.
Placed = tuple[FloatArray, FloatArray, FloatArray, FloatArray, Table]
#: A robot's shapes as :func:`declared_contacts` takes them
#: (:attr:`RobotTable.bounds`): the bounds in the shapes' own frames (centres,
#: halves, radii) and the packed :data:`Table`.
LocalBounds = tuple[FloatArray, FloatArray, FloatArray, Table]
#: Declared objects as the kernels take them (a
#: :class:`~cbp.collision.objects.PrimitiveEnvironment` builds them): their
#: swept boxes ``lower``, ``upper`` (m, 3), the ``candidates`` to test (indices),
#: their placements (m, 4, 4) and packed :data:`Table`, ``skip`` (n, m) (the
#: wanted contacts, not measured), each pair's GJK start ``guess`` (n, m, 5)
#: (:func:`pair_distance`'s), ``ahead`` (m, 3) (each object's displacement over
#: the look-ahead), whether any object moves, and the margin [m].
Obstacles = tuple[
    FloatArray,
    FloatArray,
    IntArray,
    FloatArray,
    Table,
    npt.NDArray[np.bool_],
    FloatArray,
    FloatArray,
    bool,
    float,
]
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


@numba.njit(cache=True, nogil=True, inline="always")
def _support(
    shape: PlacedConvex, hint: int, dx: float, dy: float, dz: float
) -> tuple[float, float, float, int]:
    """The core's point farthest along the world direction d, in the world.

    A hull's vertex is found by climbing its edges from vertex ``hint`` (the
    last one found, or any of the hull's): on a convex hull a vertex that no
    neighbour beats is the farthest. Returns the point and that vertex.
    """
    kind, size, frame = shape.kind, shape.size, shape.frame
    vertices, start, stop = shape.vertices, shape.start, shape.stop
    neighbor_start, neighbors = shape.neighbor_start, shape.neighbors
    lx = frame[0, 0] * dx + frame[1, 0] * dy + frame[2, 0] * dz
    ly = frame[0, 1] * dx + frame[1, 1] * dy + frame[2, 1] * dz
    lz = frame[0, 2] * dx + frame[1, 2] * dy + frame[2, 2] * dz
    px = py = pz = 0.0
    top = hint
    if kind == CONVEX:
        if top < start or top >= stop:
            top = start
        best = vertices[top, 0] * lx + vertices[top, 1] * ly + vertices[top, 2] * lz
        climbing = True
        while climbing:
            climbing = False
            for e in range(neighbor_start[top], neighbor_start[top + 1]):
                u = neighbors[e]
                v = vertices[u, 0] * lx + vertices[u, 1] * ly + vertices[u, 2] * lz
                if v > best:
                    best, top = v, u
                    climbing = True
        px, py, pz = vertices[top, 0], vertices[top, 1], vertices[top, 2]
    elif kind == BOX:
        px = size[0] if lx >= 0.0 else -size[0]
        py = size[1] if ly >= 0.0 else -size[1]
        pz = size[2] if lz >= 0.0 else -size[2]
    elif kind == CAPSULE:
        pz = size[1] if lz >= 0.0 else -size[1]
    elif kind == CYLINDER:
        across = math.sqrt(lx * lx + ly * ly)
        if across > 1e-300:
            px, py = size[0] * lx / across, size[0] * ly / across
        pz = size[1] if lz >= 0.0 else -size[1]
    return (
        frame[0, 0] * px + frame[0, 1] * py + frame[0, 2] * pz + frame[0, 3],
        frame[1, 0] * px + frame[1, 1] * py + frame[1, 2] * pz + frame[1, 3],
        frame[2, 0] * px + frame[2, 1] * py + frame[2, 2] * pz + frame[2, 3],
        top,
    )


@numba.njit(cache=True, nogil=True, inline="always")
def _support_pair(
    a: PlacedConvex,
    b: PlacedConvex,
    hint_a: int,
    hint_b: int,
    dx: float,
    dy: float,
    dz: float,
) -> tuple[float, float, float, float, float, float, int, int]:
    """A's support point along d and B's against it (A - B's along d).

    Returns A's point, B's point and the vertices found (the next hints).
    """
    pax, pay, paz, hint_a = _support(a, hint_a, dx, dy, dz)
    pbx, pby, pbz, hint_b = _support(b, hint_b, -dx, -dy, -dz)
    return pax, pay, paz, pbx, pby, pbz, hint_a, hint_b


@numba.njit(cache=True, nogil=True)
def _triangle(
    W: FloatArray, a: int, b: int, c: int
) -> tuple[float, float, float, float]:
    """Weights of triangle (a, b, c)'s point nearest the origin, its distance².

    By the triangle's Voronoi regions (vertices, edges, inside).
    """
    abx, aby, abz = W[b, 0] - W[a, 0], W[b, 1] - W[a, 1], W[b, 2] - W[a, 2]
    acx, acy, acz = W[c, 0] - W[a, 0], W[c, 1] - W[a, 1], W[c, 2] - W[a, 2]
    d1 = -(abx * W[a, 0] + aby * W[a, 1] + abz * W[a, 2])
    d2 = -(acx * W[a, 0] + acy * W[a, 1] + acz * W[a, 2])
    u = v = w = 0.0
    if d1 <= 0.0 and d2 <= 0.0:
        u = 1.0
    else:
        d3 = -(abx * W[b, 0] + aby * W[b, 1] + abz * W[b, 2])
        d4 = -(acx * W[b, 0] + acy * W[b, 1] + acz * W[b, 2])
        d5 = -(abx * W[c, 0] + aby * W[c, 1] + abz * W[c, 2])
        d6 = -(acx * W[c, 0] + acy * W[c, 1] + acz * W[c, 2])
        vc = d1 * d4 - d3 * d2
        vb = d5 * d2 - d1 * d6
        va = d3 * d6 - d5 * d4
        if d3 >= 0.0 and d4 <= d3:
            v = 1.0
        elif d6 >= 0.0 and d5 <= d6:
            w = 1.0
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
            v = d1 / (d1 - d3)
            u = 1.0 - v
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
            w = d2 / (d2 - d6)
            u = 1.0 - w
        elif va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
            w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
            v = 1.0 - w
        else:
            total = va + vb + vc
            v, w = vb / total, vc / total
            u = 1.0 - v - w
    x = u * W[a, 0] + v * W[b, 0] + w * W[c, 0]
    y = u * W[a, 1] + v * W[b, 1] + w * W[c, 1]
    z = u * W[a, 2] + v * W[b, 2] + w * W[c, 2]
    return u, v, w, x * x + y * y + z * z


@numba.njit(cache=True, nogil=True)
def _closest(W: FloatArray, n: int, lam: FloatArray) -> bool:
    """The point of the simplex W[:n] nearest the origin, as weights ``lam``.

    Returns True when the origin is inside the tetrahedron (n = 4). Weights of
    the points that are not needed are 0.
    """
    for i in range(4):
        lam[i] = 0.0
    if n == 1:
        lam[0] = 1.0
    elif n == 2:
        abx, aby, abz = W[1, 0] - W[0, 0], W[1, 1] - W[0, 1], W[1, 2] - W[0, 2]
        length2 = abx * abx + aby * aby + abz * abz
        t = -(abx * W[0, 0] + aby * W[0, 1] + abz * W[0, 2])
        t = t / length2 if length2 > 0.0 else 0.0
        t = min(max(t, 0.0), 1.0)
        lam[0], lam[1] = 1.0 - t, t
    elif n == 3:
        lam[0], lam[1], lam[2], _ = _triangle(W, 0, 1, 2)
    else:
        # Each face whose plane has the origin on the side away from the
        # fourth point; the nearest of their nearest points. None: inside.
        best = np.inf
        inside = True
        faces = ((0, 1, 2, 3), (0, 1, 3, 2), (0, 2, 3, 1), (1, 2, 3, 0))
        ax, ay, az = W[1, 0] - W[0, 0], W[1, 1] - W[0, 1], W[1, 2] - W[0, 2]
        bx, by, bz = W[2, 0] - W[0, 0], W[2, 1] - W[0, 1], W[2, 2] - W[0, 2]
        cx, cy, cz = W[3, 0] - W[0, 0], W[3, 1] - W[0, 1], W[3, 2] - W[0, 2]
        volume = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx)
        volume += az * (bx * cy - by * cx)
        scale = max(ax * ax + ay * ay + az * az, bx * bx + by * by + bz * bz)
        scale = max(scale, cx * cx + cy * cy + cz * cz)
        flat = abs(volume) <= 1e-12 * scale**1.5
        for a, b, c, d in faces:
            ex, ey, ez = W[b, 0] - W[a, 0], W[b, 1] - W[a, 1], W[b, 2] - W[a, 2]
            fx, fy, fz = W[c, 0] - W[a, 0], W[c, 1] - W[a, 1], W[c, 2] - W[a, 2]
            nx, ny, nz = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
            origin = -(nx * W[a, 0] + ny * W[a, 1] + nz * W[a, 2])
            other = (
                nx * (W[d, 0] - W[a, 0])
                + ny * (W[d, 1] - W[a, 1])
                + nz * (W[d, 2] - W[a, 2])
            )
            if not flat and origin * other >= 0.0:
                continue  # the origin is on the fourth point's side
            inside = False
            u, v, w, dist2 = _triangle(W, a, b, c)
            if dist2 < best:
                best = dist2
                lam[a], lam[b], lam[c], lam[d] = u, v, w, 0.0
        if inside:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def _compact(
    W: FloatArray, WA: FloatArray, WB: FloatArray, lam: FloatArray, n: int
) -> int:
    """Drop the simplex points of weight 0; return how many are left."""
    m = 0
    for i in range(n):
        if lam[i] > 0.0:
            if m != i:
                for a in range(3):
                    W[m, a], WA[m, a], WB[m, a] = W[i, a], WA[i, a], WB[i, a]
                lam[m] = lam[i]
            m += 1
    return m


@numba.njit(cache=True, nogil=True)
def pair_distance(
    shape_a: PlacedConvex,
    shape_b: PlacedConvex,
    guess: FloatArray,
    work: FloatArray,
    out: FloatArray,
) -> int:
    """Signed distance of shape A from shape B, witnesses and normal (B toward A).

    Args:
        shape_a: A where it stands.
        shape_b: B, likewise.
        guess: (5,): where to start, updated for the next call: the last
            normal (zeros: none yet) and the hulls' last support vertices.
            Between small motions, GJK then needs a few iterations.
        work: scratch, (16, 3) floats.
        out: (10,): distance, the point on A, the point on B, the unit normal
            from B toward A.

    Returns:
        0, or :data:`FAILED` when EPA could not start (``out`` is then unset).
    """
    W = work[0:4]
    WA = work[4:8]
    WB = work[8:12]
    lam = work[12:16, 0]
    # Start from the last call's normal and vertices, else along the line
    # between the frames' origins.
    hint_a, hint_b = int(guess[3]), int(guess[4])
    vx, vy, vz = guess[0], guess[1], guess[2]
    if vx * vx + vy * vy + vz * vz < 1e-24:
        vx = shape_a.frame[0, 3] - shape_b.frame[0, 3]
        vy = shape_a.frame[1, 3] - shape_b.frame[1, 3]
        vz = shape_a.frame[2, 3] - shape_b.frame[2, 3]
    if vx * vx + vy * vy + vz * vz < 1e-24:
        vx, vy, vz = 1.0, 0.0, 0.0
    n = 0
    vv = np.inf
    ax = ay = az = bx = by = bz = 0.0
    overlap = False
    for _ in range(_GJK_ITERATIONS):
        pax, pay, paz, pbx, pby, pbz, hint_a, hint_b = _support_pair(
            shape_a, shape_b, hint_a, hint_b, -vx, -vy, -vz
        )
        wx, wy, wz = pax - pbx, pay - pby, paz - pbz
        if n > 0:
            gap = vv - (vx * wx + vy * wy + vz * wz)
            if gap <= GJK_TOLERANCE * math.sqrt(vv) or gap <= 1e-14 * vv:
                break  # no support point brings the bound down any more
            repeated = False
            for i in range(n):
                if W[i, 0] == wx and W[i, 1] == wy and W[i, 2] == wz:
                    repeated = True
            if repeated:
                break
        W[n, 0], W[n, 1], W[n, 2] = wx, wy, wz
        WA[n, 0], WA[n, 1], WA[n, 2] = pax, pay, paz
        WB[n, 0], WB[n, 1], WB[n, 2] = pbx, pby, pbz
        n += 1
        if _closest(W, n, lam):
            overlap = True
            break
        n = _compact(W, WA, WB, lam, n)
        nx = ny = nz = 0.0
        cax = cay = caz = cbx = cby = cbz = 0.0
        for i in range(n):
            nx += lam[i] * W[i, 0]
            ny += lam[i] * W[i, 1]
            nz += lam[i] * W[i, 2]
            cax += lam[i] * WA[i, 0]
            cay += lam[i] * WA[i, 1]
            caz += lam[i] * WA[i, 2]
            cbx += lam[i] * WB[i, 0]
            cby += lam[i] * WB[i, 1]
            cbz += lam[i] * WB[i, 2]
        new = nx * nx + ny * ny + nz * nz
        if new >= vv:
            break  # no progress (round-off): keep the last point
        vx, vy, vz, vv = nx, ny, nz, new
        ax, ay, az, bx, by, bz = cax, cay, caz, cbx, cby, cbz
        if vv <= 1e-24:
            overlap = True  # touching: EPA tells how deep
            break
    if not overlap:
        core = math.sqrt(vv)
        ux, uy, uz = vx / core, vy / core, vz / core
    else:
        status = _epa(shape_a, shape_b, hint_a, hint_b, W, WA, WB, n, out)
        if status != 0:
            return status
        core = out[0]
        ax, ay, az = out[1], out[2], out[3]
        bx, by, bz = out[4], out[5], out[6]
        ux, uy, uz = out[7], out[8], out[9]
    guess[0], guess[1], guess[2] = ux, uy, uz
    guess[3], guess[4] = hint_a, hint_b
    ra, rb = shape_a.radius, shape_b.radius
    out[0] = core - ra - rb
    out[1], out[2], out[3] = ax - ra * ux, ay - ra * uy, az - ra * uz
    out[4], out[5], out[6] = bx + rb * ux, by + rb * uy, bz + rb * uz
    out[7], out[8], out[9] = ux, uy, uz
    return 0


@numba.njit(cache=True, nogil=True)
def _face_plane(P: FloatArray, faces: IntArray, f: int, plane: FloatArray) -> bool:
    """Face f's unit normal and offset into ``plane[f]``; False if degenerate."""
    a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
    ex, ey, ez = P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2]
    fx, fy, fz = P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2]
    nx, ny, nz = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
    length = math.sqrt(nx * nx + ny * ny + nz * nz)
    if length <= 1e-30:
        return False
    nx, ny, nz = nx / length, ny / length, nz / length
    plane[f, 0], plane[f, 1], plane[f, 2] = nx, ny, nz
    plane[f, 3] = nx * P[a, 0] + ny * P[a, 1] + nz * P[a, 2]
    return True


@numba.njit(cache=True, nogil=True)
def _epa(
    shape_a: PlacedConvex,
    shape_b: PlacedConvex,
    hint_a: int,
    hint_b: int,
    W: FloatArray,
    WA: FloatArray,
    WB: FloatArray,
    n: int,
    out: FloatArray,
) -> int:
    """The cores' penetration: EPA from GJK's last simplex (it holds the origin).

    Writes (the cores' signed distance, point on A, point on B, normal from B
    toward A) to ``out``; returns 0, or :data:`FAILED`.
    """
    V = _EPA_VERTICES
    P = np.empty((V, 3))
    PA = np.empty((V, 3))
    PB = np.empty((V, 3))
    faces = np.empty((_EPA_FACES, 3), dtype=np.int64)
    plane = np.empty((_EPA_FACES, 4))
    alive = np.zeros(_EPA_FACES, dtype=np.bool_)
    edges = np.empty((_EPA_EDGES, 2), dtype=np.int64)
    for i in range(n):
        for a in range(3):
            P[i, a], PA[i, a], PB[i, a] = W[i, a], WA[i, a], WB[i, a]
    # A simplex of fewer than four points (the shapes touch, or the origin is
    # on a face of the simplex): grow it to a tetrahedron by the support points
    # farthest from its span.
    directions = np.empty((6, 3))
    while n < 4:
        if n == 1:
            directions[:] = 0.0
            for a in range(3):
                directions[2 * a, a] = 1.0
                directions[2 * a + 1, a] = -1.0
            count = 6
        elif n == 2:
            ux, uy, uz = P[1, 0] - P[0, 0], P[1, 1] - P[0, 1], P[1, 2] - P[0, 2]
            # A direction across the segment, and one across both.
            if abs(ux) <= abs(uy) and abs(ux) <= abs(uz):
                qx, qy, qz = 0.0, -uz, uy
            elif abs(uy) <= abs(uz):
                qx, qy, qz = -uz, 0.0, ux
            else:
                qx, qy, qz = -uy, ux, 0.0
            rx, ry, rz = uy * qz - uz * qy, uz * qx - ux * qz, ux * qy - uy * qx
            directions[0] = qx, qy, qz
            directions[1] = -qx, -qy, -qz
            directions[2] = rx, ry, rz
            directions[3] = -rx, -ry, -rz
            count = 4
        else:
            ex, ey, ez = P[1, 0] - P[0, 0], P[1, 1] - P[0, 1], P[1, 2] - P[0, 2]
            fx, fy, fz = P[2, 0] - P[0, 0], P[2, 1] - P[0, 1], P[2, 2] - P[0, 2]
            nx, ny, nz = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
            directions[0] = nx, ny, nz
            directions[1] = -nx, -ny, -nz
            count = 2
        best = 0.0
        bax = bay = baz = bbx = bby = bbz = 0.0
        for k in range(count):
            dx, dy, dz = directions[k, 0], directions[k, 1], directions[k, 2]
            pax, pay, paz, pbx, pby, pbz, hint_a, hint_b = _support_pair(
                shape_a, shape_b, hint_a, hint_b, dx, dy, dz
            )
            P[n, 0], P[n, 1], P[n, 2] = pax - pbx, pay - pby, paz - pbz
            reach = _off_span(P, n)
            if reach > best:
                best = reach
                bax, bay, baz, bbx, bby, bbz = pax, pay, paz, pbx, pby, pbz
        if best <= 1e-9:
            return FAILED
        PA[n, 0], PA[n, 1], PA[n, 2] = bax, bay, baz
        PB[n, 0], PB[n, 1], PB[n, 2] = bbx, bby, bbz
        P[n, 0], P[n, 1], P[n, 2] = bax - bbx, bay - bby, baz - bbz
        n += 1
    # The tetrahedron's faces, turned outward.
    tetra = ((0, 1, 2), (0, 3, 1), (0, 2, 3), (1, 3, 2))
    cx = 0.25 * (P[0, 0] + P[1, 0] + P[2, 0] + P[3, 0])
    cy = 0.25 * (P[0, 1] + P[1, 1] + P[2, 1] + P[3, 1])
    cz = 0.25 * (P[0, 2] + P[1, 2] + P[2, 2] + P[3, 2])
    for f in range(4):
        a, b, c = tetra[f]
        faces[f, 0], faces[f, 1], faces[f, 2] = a, b, c
        if not _face_plane(P, faces, f, plane):
            return FAILED
        if plane[f, 0] * cx + plane[f, 1] * cy + plane[f, 2] * cz > plane[f, 3]:
            faces[f, 1], faces[f, 2] = c, b
            _face_plane(P, faces, f, plane)
        alive[f] = True
    face_count = 4
    nearest = 0
    for _ in range(_EPA_VERTICES - 4):
        nearest = -1
        least = np.inf
        for f in range(face_count):
            if alive[f] and plane[f, 3] < least:
                least, nearest = plane[f, 3], f
        if nearest < 0:
            return FAILED
        dx, dy, dz = plane[nearest, 0], plane[nearest, 1], plane[nearest, 2]
        pax, pay, paz, pbx, pby, pbz, hint_a, hint_b = _support_pair(
            shape_a, shape_b, hint_a, hint_b, dx, dy, dz
        )
        wx, wy, wz = pax - pbx, pay - pby, paz - pbz
        if dx * wx + dy * wy + dz * wz - least <= EPA_TOLERANCE:
            break  # the nearest face is on the boundary
        if n == _EPA_VERTICES or face_count + 3 * n > _EPA_FACES:
            break  # out of room: the nearest face so far
        P[n, 0], P[n, 1], P[n, 2] = wx, wy, wz
        PA[n, 0], PA[n, 1], PA[n, 2] = pax, pay, paz
        PB[n, 0], PB[n, 1], PB[n, 2] = pbx, pby, pbz
        # The faces the new point sees go; their edges seen once are the horizon.
        count = 0
        for f in range(face_count):
            if not alive[f]:
                continue
            seen = plane[f, 0] * wx + plane[f, 1] * wy + plane[f, 2] * wz
            if seen - plane[f, 3] > 1e-14 * max(1.0, abs(plane[f, 3])):
                alive[f] = False
                for e in range(3):
                    if count < _EPA_EDGES:
                        edges[count, 0] = faces[f, e]
                        edges[count, 1] = faces[f, (e + 1) % 3]
                        count += 1
        added = 0
        for e in range(count):
            a, b = edges[e, 0], edges[e, 1]
            shared = False
            for g in range(count):
                if edges[g, 0] == b and edges[g, 1] == a:
                    shared = True
                    break
            if shared:
                continue
            f = face_count
            faces[f, 0], faces[f, 1], faces[f, 2] = a, b, n
            alive[f] = _face_plane(P, faces, f, plane)
            face_count += 1
            added += 1
        if added == 0:
            return FAILED
        n += 1
    # The origin's projection on the nearest face, in barycentric weights.
    # Faces in one plane (a face of A - B cut in triangles) are equally near:
    # the one the projection falls in gives the witness points.
    depth = plane[nearest, 3]
    px, py, pz = (
        depth * plane[nearest, 0],
        depth * plane[nearest, 1],
        depth * plane[nearest, 2],
    )
    f = nearest
    u, v, w = _barycentric(P, faces[f, 0], faces[f, 1], faces[f, 2], px, py, pz)
    worst = min(u, v, w)
    if worst < 0.0:
        for g in range(face_count):
            if not alive[g] or g == nearest or plane[g, 3] > depth + EPA_TOLERANCE:
                continue
            if (
                plane[g, 0] * plane[nearest, 0]
                + plane[g, 1] * plane[nearest, 1]
                + plane[g, 2] * plane[nearest, 2]
                < 1.0 - 1e-9
            ):
                continue
            gu, gv, gw = _barycentric(
                P, faces[g, 0], faces[g, 1], faces[g, 2], px, py, pz
            )
            if min(gu, gv, gw) > worst:
                f, u, v, w, worst = g, gu, gv, gw, min(gu, gv, gw)
    # What round-off leaves outside the face is clipped back to it.
    u, v, w = max(u, 0.0), max(v, 0.0), max(w, 0.0)
    total = u + v + w
    u, v, w = u / total, v / total, w / total
    a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
    for k in range(3):
        out[1 + k] = u * PA[a, k] + v * PA[b, k] + w * PA[c, k]
        out[4 + k] = u * PB[a, k] + v * PB[b, k] + w * PB[c, k]
        # The normal from B toward A is the way out: against the face's.
        out[7 + k] = -plane[nearest, k]
    out[0] = -depth
    return 0


@numba.njit(cache=True, nogil=True)
def _off_span(P: FloatArray, n: int) -> float:
    """How far P[n] lies from the affine span of P[:n] (n = 1, 2 or 3)."""
    dx, dy, dz = P[n, 0] - P[0, 0], P[n, 1] - P[0, 1], P[n, 2] - P[0, 2]
    if n == 1:
        return math.sqrt(dx * dx + dy * dy + dz * dz)
    ux, uy, uz = P[1, 0] - P[0, 0], P[1, 1] - P[0, 1], P[1, 2] - P[0, 2]
    if n == 2:
        cx, cy, cz = dy * uz - dz * uy, dz * ux - dx * uz, dx * uy - dy * ux
        length = math.sqrt(ux * ux + uy * uy + uz * uz)
        return math.sqrt(cx * cx + cy * cy + cz * cz) / max(length, 1e-300)
    vx, vy, vz = P[2, 0] - P[0, 0], P[2, 1] - P[0, 1], P[2, 2] - P[0, 2]
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    length = math.sqrt(nx * nx + ny * ny + nz * nz)
    reach: float = abs(nx * dx + ny * dy + nz * dz) / max(length, 1e-300)
    return reach


@numba.njit(cache=True, nogil=True)
def _barycentric(
    P: FloatArray, a: int, b: int, c: int, px: float, py: float, pz: float
) -> tuple[float, float, float]:
    """Barycentric weights of p in the plane of triangle a, b, c (negative outside)."""
    e0x, e0y, e0z = P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2]
    e1x, e1y, e1z = P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2]
    e2x, e2y, e2z = px - P[a, 0], py - P[a, 1], pz - P[a, 2]
    d00 = e0x * e0x + e0y * e0y + e0z * e0z
    d01 = e0x * e1x + e0y * e1y + e0z * e1z
    d11 = e1x * e1x + e1y * e1y + e1z * e1z
    d20 = e2x * e0x + e2y * e0y + e2z * e0z
    d21 = e2x * e1x + e2y * e1y + e2z * e1z
    denominator = d00 * d11 - d01 * d01
    if denominator <= 0.0:
        return 1.0, 0.0, 0.0
    v = (d11 * d20 - d01 * d21) / denominator
    w = (d00 * d21 - d01 * d20) / denominator
    return 1.0 - v - w, v, w


@numba.njit(cache=True, nogil=True, inline="always")
def _placed(table: Table, frames: FloatArray, s: int) -> PlacedConvex:
    """Shape s of a packed table at its placement ``frames[s]``."""
    kind, size, radius, vertex_start, vertices, neighbor_start, neighbors = table
    return PlacedConvex(
        kind[s],
        size[s],
        radius[s],
        vertices,
        vertex_start[s],
        vertex_start[s + 1],
        neighbor_start,
        neighbors,
        frames[s],
    )


@numba.njit(cache=True, nogil=True, inline="always")
def _measure(
    a: PlacedConvex,
    b: PlacedConvex,
    guess: FloatArray,
    work: FloatArray,
    out: FloatArray,
) -> int:
    """:func:`pair_distance`, or :data:`FAILED` for a shape the kernels skip."""
    if a.kind == UNSUPPORTED or b.kind == UNSUPPORTED:
        return FAILED
    return pair_distance(a, b, guess, work, out)


@numba.njit(cache=True, nogil=True, inline="always")
def _write(floats: FloatArray, row: int, out: FloatArray, distance: float) -> None:
    """A contact into ``floats`` (4, K, 3): points, normal, then the distance."""
    for k in range(3):
        floats[0, row, k] = out[1 + k]
        floats[1, row, k] = out[4 + k]
        floats[2, row, k] = out[7 + k]
    floats[3, row, 0] = distance


@numba.njit(cache=True, nogil=True, inline="always")
def obstacle_contacts(
    robot: Placed,
    objects: Obstacles,
    index: IntArray,
    floats: FloatArray,
    left: IntArray,
) -> tuple[int, int]:
    """The robot shapes' contacts with declared objects, broad and narrow phase.

    The pairs :func:`~cbp.collision.broad.near_objects` keeps, except those
    the objects skip (wanted contacts), are measured (each from its
    ``guess``, :func:`pair_distance`'s); those nearer than the margin are
    written: ``index`` (2, K) the shape and the object, ``floats`` (4, K, 3)
    the point on the shape, the point on the object, the unit normal from the
    object toward the shape and (``[3, :, 0]``) the distance. A moving
    object's distance is less its approach along the normal (its displacement
    over the look-ahead, ``ahead``).

    Pairs with a shape the kernels do not measure, or that EPA could not start
    on, are written to ``left`` (2, L), (shape, object), for coal.

    Returns:
        (contacts written, pairs left for coal).
    """
    centres, halves, radii, frames, table = robot
    lower, upper, candidates, object_frames, object_table = objects[:5]
    skip, guess, ahead, moving, margin = objects[5:]
    near_shape, near_object = near_objects(
        centres, halves, radii, lower, upper, candidates, margin
    )
    work = np.empty((16, 3))
    out = np.empty(10)
    count = 0
    missed = 0
    for p in range(len(near_shape)):
        s, k = near_shape[p], near_object[p]
        if skip[s, k]:
            continue
        status = _measure(
            _placed(table, frames, s),
            _placed(object_table, object_frames, k),
            guess[s, k],
            work,
            out,
        )
        if status != 0:
            left[0, missed], left[1, missed] = s, k
            missed += 1
            continue
        d = out[0]
        if moving:
            d -= max(
                out[7] * ahead[k, 0] + out[8] * ahead[k, 1] + out[9] * ahead[k, 2],
                0.0,
            )
        if d < margin:
            index[0, count], index[1, count] = s, k
            _write(floats, count, out, d)
            count += 1
    return count, missed


@numba.njit(cache=True, nogil=True, inline="always")
def self_contacts(
    robot: Placed,
    pairs: SelfPairs,
    index: IntArray,
    floats: FloatArray,
    left: IntArray,
) -> tuple[int, int]:
    """The contacts between the robot's own shape pairs (``first``, ``second``).

    The pairs :func:`~cbp.collision.broad.near_pairs` keeps within the
    pairs' margin are measured (each from its ``self_guess``), shape
    ``second`` as B (the normal points from it toward ``first``); those nearer
    than the margin are written as :func:`obstacle_contacts` writes them,
    their distance less the pairs' padding. Pairs the kernels cannot measure
    go to ``left`` (2, L): -1, then the index into the pairs.

    Returns:
        (contacts written, pairs left for coal).
    """
    centres, halves, radii, frames, table = robot
    first, second, self_guess, margin, padding = pairs
    near = np.empty(len(first), dtype=np.intp)
    found = near_pairs(centres, halves, radii, first, second, margin, near)
    work = np.empty((16, 3))
    out = np.empty(10)
    count = 0
    missed = 0
    for p in range(found):
        i, j = first[near[p]], second[near[p]]
        status = _measure(
            _placed(table, frames, i),
            _placed(table, frames, j),
            self_guess[near[p]],
            work,
            out,
        )
        if status != 0:
            left[0, missed], left[1, missed] = -1, near[p]
            missed += 1
        elif out[0] < margin:
            index[0, count], index[1, count] = i, j
            _write(floats, count, out, out[0] - padding)
            count += 1
    return count, missed


@numba.njit(cache=True, nogil=True)
def declared_contacts(
    frames: FloatArray,
    bounds: LocalBounds,
    objects: Obstacles,
    padding: float,
    pairs: SelfPairs,
    index: IntArray,
    floats: FloatArray,
    left: IntArray,
) -> tuple[int, int, int, int, int]:
    """A whole contact query against declared objects, in one call.

    The shapes' bounds from their world placements ``frames`` (n, 4, 4) and
    ``bounds`` in their own frames (:func:`~cbp.collision.broad.shape_bounds`),
    then :func:`obstacle_contacts` with distances less ``padding``, then
    :func:`self_contacts` of the ``pairs`` (none when empty).

    The contacts are written in order, obstacles first: ``index`` (2, K) holds
    the shape and the other shape (-1 for objects), ``floats`` (4, K, 3) the
    points, normals and distances as :func:`obstacle_contacts` writes them.
    ``left`` (2, L) gets the pairs left for coal: (shape, object) first, then
    (-1, self pair index).

    Returns:
        (obstacle contacts, self contacts, obstacle pairs left, self pairs left,
        the most obstacle contacts of any one shape).
    """
    centres_local, halves_local, radii, table = bounds
    n = len(frames)
    centres = np.empty((n, 3))
    halves = np.empty((n, 3))
    shape_bounds(frames, centres_local, halves_local, centres, halves)
    robot = (centres, halves, radii, frames, table)
    obstacles, obstacles_missed = obstacle_contacts(robot, objects, index, floats, left)
    per_shape = np.zeros(n, dtype=np.intp)
    most = 0
    for c in range(obstacles):
        index[1, c] = -1
        floats[3, c, 0] -= padding
        s = index[0, c]
        per_shape[s] += 1
        most = max(most, per_shape[s])
    own = own_missed = 0
    if len(pairs[0]):
        own, own_missed = self_contacts(
            robot,
            pairs,
            index[:, obstacles:],
            floats[:, obstacles:],
            left[:, obstacles_missed:],
        )
    return obstacles, own, obstacles_missed, own_missed, most


@numba.njit(cache=True, nogil=True)
def self_overlap(frames: FloatArray, bounds: LocalBounds, pairs: SelfPairs) -> int:
    """Whether two of the robot's shapes come nearer than the pairs' margin.

    The planners' yes-or-no self check: the shapes placed by ``frames``
    (n, 4, 4), the ``pairs`` the broad phase keeps measured in turn until the
    first nearer than their margin (``pairs``' fourth field; twice the padding
    checks the padded shapes for overlap).

    Returns:
        1 for a pair that near, 0 for none, -1 when a pair could not be
        measured (a shape the kernels skip) and none was found nearer.
    """
    centres_local, halves_local, radii, table = bounds
    first, second, self_guess, margin, _ = pairs
    n = len(frames)
    centres = np.empty((n, 3))
    halves = np.empty((n, 3))
    shape_bounds(frames, centres_local, halves_local, centres, halves)
    near = np.empty(len(first), dtype=np.intp)
    found = near_pairs(centres, halves, radii, first, second, margin, near)
    work = np.empty((16, 3))
    out = np.empty(10)
    answer = 0
    for p in range(found):
        k = near[p]
        status = _measure(
            _placed(table, frames, first[k]),
            _placed(table, frames, second[k]),
            self_guess[k],
            work,
            out,
        )
        if status != 0:
            answer = -1
        elif out[0] < margin:
            return 1
    return answer


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


def placed_robot(robot: PlacedShapes) -> Placed:
    """A placed robot as the kernels take it (:data:`Placed`)."""
    return (
        robot.centres,
        robot.halves,
        robot.radii,
        robot.placements.homogeneous,
        fields(packed_robot(robot.shapes)),
    )


def compile_convex_kernels() -> None:
    """Compile the kernels (or load them from numba's cache) on tiny inputs."""
    shapes = fields(
        pack_shapes(
            [
                coal.Box(0.1, 0.1, 0.1),
                coal.Sphere(0.05),
                coal.Capsule(0.05, 0.1),
                coal.Cylinder(0.05, 0.1),
            ]
        )
    )
    frames = np.tile(np.eye(4), (4, 1, 1))
    frames[:, 0, 3] = 0.0, 0.2, 0.4, 0.6
    centres = np.ascontiguousarray(frames[:, :3, 3])
    halves = np.full((4, 3), 0.1)
    radii = np.full(4, 0.2)
    robot = (centres, halves, radii, frames, shapes)
    first = np.array([0, 1], dtype=np.intp)
    pairs = (first, first + 2, np.zeros((2, 5)), 0.1, 0.01)
    for moving in (False, True):
        # The same shapes as objects, every one a candidate.
        objects = (
            centres - 0.1,
            centres + 0.1,
            np.arange(4, dtype=np.intp),
            frames,
            shapes,
            np.zeros((4, 4), dtype=np.bool_),
            np.zeros((4, 4, 5)),
            np.zeros((4, 3)),
            moving,
            0.1,
        )
        obstacle_contacts(robot, objects, *contact_buffers(32))
        declared_contacts(
            frames,
            (centres, halves, radii, shapes),
            objects,
            0.01,
            pairs,
            *contact_buffers(32),
        )
    self_contacts(robot, pairs, *contact_buffers(32))


def contact_buffers(n: int) -> tuple[IntArray, FloatArray, IntArray]:
    """Room for ``n`` contacts as the contact kernels write them.

    ``index`` (2, n) and ``floats`` (4, n, 3), as
    :meth:`~cbp.collision.contacts.ContactSet.packed` reads them, and ``left``
    (2, n), the pairs the kernels leave to coal.
    """
    return (
        np.empty((2, n), dtype=np.intp),
        np.empty((4, n, 3)),
        np.empty((2, n), dtype=np.intp),
    )


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
