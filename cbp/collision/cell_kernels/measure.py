# SPDX-License-Identifier: Apache-2.0
"""A point's distance to a robot shape, in the shape's frame: hulls and capsules.

A hull's distance is its largest excess over the face planes, read from the
face grid around the point (:func:`hull_excess`, the package's docstring); a
capsule's is the distance to its axis less its radius. :class:`Shapes` holds a
robot's shapes packed for the kernels
(:class:`~cbp.collision.shape_table.ShapeTable` builds it), with the helpers
that place a shape's frame and box in the world.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
import numpy.typing as npt

from cbp.robot import FloatArray, IntArray

__all__ = [
    "CAPSULE",
    "EXACT_WITHIN",
    "HULL",
    "VALUE_UNIT",
    "Shapes",
    "capsule_excess",
    "face_grid",
    "hull_excess",
    "hull_excesses",
    "shape_frame",
    "world_box",
]

#: Shape kinds in :attr:`Shapes.kind`.
HULL, CAPSULE = 0, 1
#: Cells nearer than this to a hull [m] are measured against the faces of all
#: eight grid points around them; farther ones, against their nearest's.
EXACT_WITHIN = 0.02
#: The unit of the face grids' values [m].
VALUE_UNIT = 1e-3


class Shapes(NamedTuple):
    """Robot shapes packed for the cell kernels (fields as in ShapeTable)."""

    kind: npt.NDArray[np.int64]
    to_frame: FloatArray
    lower: FloatArray
    upper: FloatArray
    capsule: FloatArray
    planes: FloatArray
    plane_start: npt.NDArray[np.int64]
    grid_origin: FloatArray
    grid_dims: npt.NDArray[np.int64]
    grid_start: npt.NDArray[np.int64]
    faces: npt.NDArray[np.int16]
    values: npt.NDArray[np.uint8]
    step: float


@numba.njit(cache=True, nogil=True, inline="always")
def capsule_excess(
    x: float,
    y: float,
    z: float,
    radius: float,
    half_length: float,
    directions: FloatArray,
    half: float,
    margin: float,
) -> tuple[float, int, float, float, float]:
    """A point's distance to a capsule along z (in its frame), group and normal.

    The group is the direction of ``directions`` nearest to the capsule's
    outward unit normal toward the point; not looked for (0, and a zero
    normal) where the distance less ``half`` is ``margin`` or more.
    """
    on_axis = min(max(z, -half_length), half_length)
    ox, oy, oz = x, y, z - on_axis
    length = math.sqrt(ox * ox + oy * oy + oz * oz)
    if length - radius - half >= margin:  # too far to keep: no group needed
        return length - radius, 0, 0.0, 0.0, 0.0
    if length < 1e-12:  # on the axis: take x
        ox, oy, oz, length = 1.0, 0.0, 0.0, 1.0
    ox, oy, oz = ox / length, oy / length, oz / length
    group = 0
    top = -np.inf
    for g in range(len(directions)):
        v = directions[g, 0] * ox + directions[g, 1] * oy + directions[g, 2] * oz
        if v > top:
            top, group = v, g
    return length - radius, group, ox, oy, oz


@numba.njit(cache=True, nogil=True, inline="always")
def hull_excess(
    x: float,
    y: float,
    z: float,
    planes: FloatArray,
    faces: npt.NDArray[np.int16],
    values: npt.NDArray[np.uint8],
    gx: float,
    gy: float,
    gz: float,
    ny: int,
    nz: int,
    inv_step: float,
    cutoff: float,
    exact_within: float,
) -> tuple[float, int]:
    """A point's excess over a hull's faces (in its frame), and the face.

    ``planes``, ``faces`` and ``values`` are the hull's; its grid starts at
    (gx, gy, gz) with ``ny`` x ``nz`` points per x slab. The point must lie in
    the hull's grown box: the grid reaches a step beyond it on every side, so
    no index is clamped (clamping took 5 % of a query). The excess is the
    largest over the faces stored at the eight grid points around the point; it
    is ``inf`` (face -1) when the nearest grid point's value shows the excess is
    at least ``cutoff`` (both in ``VALUE_UNIT``) less the distance to that point
    (the excess changes by at most the distance moved). Where the excess over
    the nearest grid point's face is at least ``exact_within`` [m], that excess
    is returned.
    """
    fx = (x - gx) * inv_step
    fy = (y - gy) * inv_step
    fz = (z - gz) * inv_step
    # The nearest grid point first: most cells stop there.
    near = (int(fx + 0.5) * ny + int(fy + 0.5)) * nz + int(fz + 0.5)
    if values[near] >= cutoff:  # in VALUE_UNIT
        return np.inf, -1
    face = int(faces[near])
    depth = (
        planes[face, 0] * x
        + planes[face, 1] * y
        + planes[face, 2] * z
        - planes[face, 3]
    )
    if depth >= exact_within:  # far: a lower bound is enough
        return depth, face
    ix, iy, iz = int(fx), int(fy), int(fz)
    for cx in range(2):
        for cy in range(2):
            base = ((ix + cx) * ny + iy + cy) * nz + iz
            for cz in range(2):
                f = int(faces[base + cz])
                v = (
                    planes[f, 0] * x
                    + planes[f, 1] * y
                    + planes[f, 2] * z
                    - planes[f, 3]
                )
                if v > depth:
                    depth = v
                    face = f
    return depth, face


@numba.njit(cache=True, nogil=True)
def hull_excesses(
    shapes: Shapes,
    s: int,
    points: FloatArray,
    exact_within: float,
    depth: FloatArray,
    face: IntArray,
) -> None:
    """Points' excess over hull ``s``'s faces (points in its frame), and the face.

    Measured as :func:`~cbp.collision.cell_kernels.candidates` measures cells
    (``exact_within`` as there). The points must lie in the hull's grown box
    (``shapes.lower``, ``upper``); one outside raises ValueError (its grid index
    would be out of range).
    """
    lower, upper = shapes.lower[s], shapes.upper[s]
    for k in range(len(points)):
        for a in range(3):
            if not lower[a] <= points[k, a] <= upper[a]:
                raise ValueError("a point outside the hull's grown box")
    planes = shapes.planes[shapes.plane_start[s] : shapes.plane_start[s + 1]]
    faces = shapes.faces[shapes.grid_start[s] : shapes.grid_start[s + 1]]
    values = shapes.values[shapes.grid_start[s] : shapes.grid_start[s + 1]]
    origin, dims = shapes.grid_origin[s], shapes.grid_dims[s]
    inv_step = 1.0 / shapes.step
    for k in range(len(points)):
        depth[k], face[k] = hull_excess(
            points[k, 0],
            points[k, 1],
            points[k, 2],
            planes,
            faces,
            values,
            origin[0],
            origin[1],
            origin[2],
            dims[1],
            dims[2],
            inv_step,
            np.inf,
            exact_within,
        )


@numba.njit(cache=True, nogil=True)
def face_grid(
    normals: npt.NDArray[np.float32],
    offsets: npt.NDArray[np.float32],
    origin: FloatArray,
    dims: npt.NDArray[np.int64],
    step: float,
    faces: npt.NDArray[np.int16],
    values: npt.NDArray[np.float32],
) -> None:
    """A hull's largest face and its excess at every point of a grid (x major).

    ``normals`` (n, 3) and ``offsets`` (n,): the hull's face planes (float32);
    the grid starts at ``origin`` with ``dims`` points ``step`` apart. Points
    and excesses are float32, and the first of equal faces wins, as a float32
    product and argmax would give.
    """
    nx, ny, nz = dims[0], dims[1], dims[2]
    count = len(offsets)
    k = 0
    for i in range(nx):
        x = np.float32(origin[0] + step * i)
        for j in range(ny):
            y = np.float32(origin[1] + step * j)
            for m in range(nz):
                z = np.float32(origin[2] + step * m)
                best = np.float32(-np.inf)
                face = 0
                for f in range(count):
                    v = (
                        x * normals[f, 0] + y * normals[f, 1] + z * normals[f, 2]
                    ) - offsets[f]
                    if v > best:
                        best = v
                        face = f
                faces[k] = face
                values[k] = best
                k += 1


@numba.njit(cache=True, nogil=True, inline="always")
def shape_frame(
    frames: FloatArray, to_frame: FloatArray, s: int, M: FloatArray
) -> None:
    """Shape ``s``'s frame in the world into ``M``: its placement x ``to_frame``."""
    for i in range(4):
        for j in range(4):
            M[i, j] = (
                frames[s, i, 0] * to_frame[s, 0, j]
                + frames[s, i, 1] * to_frame[s, 1, j]
                + frames[s, i, 2] * to_frame[s, 2, j]
                + frames[s, i, 3] * to_frame[s, 3, j]
            )


@numba.njit(cache=True, nogil=True, inline="always")
def world_box(
    M: FloatArray, lx: float, ly: float, lz: float, ux: float, uy: float, uz: float
) -> tuple[float, float, float, float, float, float]:
    """The world box about box ``l``-``u`` of frame ``M``: centre, half extents."""
    cx, cy, cz = 0.5 * (lx + ux), 0.5 * (ly + uy), 0.5 * (lz + uz)
    ex, ey, ez = 0.5 * (ux - lx), 0.5 * (uy - ly), 0.5 * (uz - lz)
    r00, r01, r02 = M[0, 0], M[0, 1], M[0, 2]
    r10, r11, r12 = M[1, 0], M[1, 1], M[1, 2]
    r20, r21, r22 = M[2, 0], M[2, 1], M[2, 2]
    return (
        r00 * cx + r01 * cy + r02 * cz + M[0, 3],
        r10 * cx + r11 * cy + r12 * cz + M[1, 3],
        r20 * cx + r21 * cy + r22 * cz + M[2, 3],
        abs(r00) * ex + abs(r01) * ey + abs(r02) * ez,
        abs(r10) * ex + abs(r11) * ey + abs(r12) * ez,
        abs(r20) * ex + abs(r21) * ey + abs(r22) * ez,
    )
