# SPDX-License-Identifier: Apache-2.0
"""One packed shape where it stands, and its support point along a direction.

Inside the kernels a shape is a :class:`PlacedConvex` (:func:`placed` takes
one from a packed table), and :func:`support_pair` gives the support point of
A - B along a direction, for GJK and EPA alike. A hull's support point is
found by climbing its edges from the last one (a few dot products instead of
one per vertex).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba

from cbp.collision.convex_kernels.packing import BOX, CAPSULE, CONVEX, CYLINDER, Table
from cbp.robot import FloatArray, IntArray

__all__ = ["PlacedConvex", "placed", "support", "support_pair"]


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


@numba.njit(cache=True, nogil=True, inline="always")
def support(
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
def support_pair(
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
    pax, pay, paz, hint_a = support(a, hint_a, dx, dy, dz)
    pbx, pby, pbz, hint_b = support(b, hint_b, -dx, -dy, -dz)
    return pax, pay, paz, pbx, pby, pbz, hint_a, hint_b


@numba.njit(cache=True, nogil=True, inline="always")
def placed(table: Table, frames: FloatArray, s: int) -> PlacedConvex:
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
