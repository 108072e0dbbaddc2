# SPDX-License-Identifier: Apache-2.0
"""Which points lie inside the robot's shapes, compiled over stacked half-spaces.

The shapes as :class:`~cbp.collision.geometry.WorldShapes` gives them: each
shape's face planes ``n . x <= d`` placed in the world, stacked, with its
bounding sphere. A point is tested against a shape's planes only when its
(grown) sphere holds it. The map's kernels inline these tests in their loops.
"""

from __future__ import annotations

import numba
import numpy as np

from cbp.robot import FloatArray, IntArray

__all__ = ["inside_any", "inside_convex", "place_shapes", "points_inside"]


@numba.njit(cache=True, nogil=True)
def place_shapes(
    local_planes: FloatArray,
    plane_start: IntArray,
    local_centres: FloatArray,
    frames: FloatArray,
    planes: FloatArray,
    centres: FloatArray,
) -> None:
    """Write each shape's planes and sphere centre placed by its frame (S, 4, 4)."""
    for s in range(frames.shape[0]):
        R = frames[s, :3, :3]
        t = frames[s, :3, 3]
        for p in range(plane_start[s], plane_start[s + 1]):
            d = local_planes[p, 3]
            for a in range(3):
                n = (
                    R[a, 0] * local_planes[p, 0]
                    + R[a, 1] * local_planes[p, 1]
                    + R[a, 2] * local_planes[p, 2]
                )
                planes[p, a] = n
                d += n * t[a]
            planes[p, 3] = d
        for a in range(3):
            centres[s, a] = (
                R[a, 0] * local_centres[s, 0]
                + R[a, 1] * local_centres[s, 1]
                + R[a, 2] * local_centres[s, 2]
                + t[a]
            )


@numba.njit(cache=True, nogil=True, inline="always")
def inside_convex(
    x: float,
    y: float,
    z: float,
    planes: FloatArray,
    start: int,
    stop: int,
    grow: float,
) -> bool:
    """Whether (x, y, z) is within ``grow`` of every plane of rows [start, stop)."""
    for p in range(start, stop):
        if planes[p, 0] * x + planes[p, 1] * y + planes[p, 2] * z - planes[p, 3] > grow:
            return False
    return True


@numba.njit(cache=True, nogil=True, inline="always")
def inside_any(
    x: float,
    y: float,
    z: float,
    planes: FloatArray,
    plane_start: IntArray,
    centres: FloatArray,
    radii: FloatArray,
    grow: FloatArray,
    extra: float = 0.0,
) -> bool:
    """Whether (x, y, z) is inside some shape s grown by ``grow[s] + extra``.

    The shapes as :class:`~cbp.collision.geometry.WorldShapes` gives them:
    each bounding sphere first, then the planes of the shapes whose grown
    sphere holds the point.
    """
    for s in range(radii.size):
        grown = grow[s] + extra
        dx, dy, dz = x - centres[s, 0], y - centres[s, 1], z - centres[s, 2]
        reach = radii[s] + grown
        if dx * dx + dy * dy + dz * dz > reach * reach:
            continue
        if inside_convex(x, y, z, planes, plane_start[s], plane_start[s + 1], grown):
            return True
    return False


@numba.njit(cache=True, nogil=True)
def points_inside(
    points: FloatArray,
    planes: FloatArray,
    plane_start: IntArray,
    centres: FloatArray,
    radii: FloatArray,
    grow: FloatArray,
    out: np.ndarray,
) -> int:
    """Flag the points (n, 3) inside some shape s grown by ``grow[s]``; count them.

    The shapes as :class:`~cbp.collision.geometry.WorldShapes` gives them; a
    point within ``grow[s]`` of every face plane of shape s counts as inside
    (exact on faces, a little generous at edges and corners).
    """
    count = 0
    for n in range(points.shape[0]):
        out[n] = inside_any(
            points[n, 0],
            points[n, 1],
            points[n, 2],
            planes,
            plane_start,
            centres,
            radii,
            grow,
        )
        if out[n]:
            count += 1
    return count
