# SPDX-License-Identifier: Apache-2.0
"""What a camera would see from a pose: the prediction a look is chosen by.

A point is in sight when it lies within the camera's field of view and range
and the line to it is clear: no occupied cell of the map on it, and no part of
the robot (as it stands when the camera looks) in the way. Unseen cells on the
line may be free or not; a line that crosses a length ``u`` of unseen space
reaches its point with a chance of ``exp(-u / UNSEEN_DEPTH)``. So a point at
the edge of what is seen (the frontier) counts fully, and one deep in unseen
space, perhaps behind a surface no camera has mapped yet, counts little: a
look is chosen for what it will reveal, not for what it would see were all
unseen space empty.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
import pinocchio as pin

from cbp.collision.geometry import WorldShapes, inside_convex
from cbp.perception.kernels import OCCUPIED, UNKNOWN
from cbp.perception.spec import CameraSpec
from cbp.robot import FloatArray, IntArray

__all__ = ["UNSEEN_DEPTH", "CellStates", "in_view", "visibility"]

#: The length of unseen space a line of sight crosses with a chance 1/e [m].
UNSEEN_DEPTH = 0.05


class CellStates(NamedTuple):
    """A map's cell states as :func:`visibility` reads them.

    Cell ``(i, j, k)`` of ``cells`` (nx, ny, nz; :data:`~cbp.perception.kernels.FREE`,
    :data:`UNKNOWN` or :data:`OCCUPIED`) spans ``lower + (i, j, k) * cell`` to
    one cell beyond; outside the grid everything is unknown (the map's
    bounds: nothing is seen there).
    """

    cells: np.ndarray
    lower: FloatArray
    cell: float


def visibility(
    camera: pin.SE3,
    spec: CameraSpec,
    points: FloatArray,
    grid: CellStates,
    body: WorldShapes | None = None,
    grow: float = 0.0,
) -> FloatArray:
    """The chance (n,) that a camera at ``camera`` (optical frame) sees ``points``.

    0 outside its field of view (the spec's vertical angle, its image's
    aspect) and range, behind an occupied cell or behind the robot; else
    ``exp(-u / UNSEEN_DEPTH)`` for the length ``u`` of unseen cells on the
    line. The point's own cell and the one before it do not count. Each line
    is sampled every half cell (or less: the longest line's spacing) in one
    compiled pass.

    Args:
        camera: the camera's optical pose (+z along its axis).
        spec: the camera.
        points: the points (n, 3).
        grid: the map's cell states.
        body: the robot's shapes where the camera looks from (None: nothing
            of the robot in the way). Points nearer the camera than its
            ``near`` are not asked: the camera sits on the robot.
        grow: how much the shapes are grown [m] (0: as they are).
    """
    points = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)
    inside = in_view(camera, spec, points)
    out = np.zeros(len(points))
    if not inside.any():
        return out
    eye = np.ascontiguousarray(camera.translation, dtype=float)
    seen = points[inside]
    length = np.linalg.norm(seen - eye, axis=1)
    samples = max(2, int(np.max(length) / (0.5 * grid.cell)))
    shapes = body or _NO_BODY
    chance = np.empty(len(seen))
    _lines_of_sight(
        eye,
        seen,
        np.ascontiguousarray(grid.cells),
        np.asarray(grid.lower, dtype=float),
        float(grid.cell),
        samples,
        float(spec.near),
        shapes.planes,
        shapes.plane_start,
        shapes.centres,
        shapes.radii,
        float(grow),
        chance,
    )
    out[inside] = chance
    return out


def in_view(camera: pin.SE3, spec: CameraSpec, points: FloatArray) -> np.ndarray:
    """Whether each of ``points`` (n, 3) is in the camera's field of view and range.

    Within the spec's vertical angle and its image's aspect, and between its
    ``near`` and ``far`` along the axis, from ``camera`` (the optical pose,
    +z along its axis); nothing on the way is asked.
    """
    local = (points - camera.translation) @ camera.rotation  # into the camera
    z = local[:, 2]
    half = np.tan(np.deg2rad(spec.fov_deg) / 2.0)
    aspect = spec.width / spec.height
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(
            (z > spec.near)
            & (z < spec.far)
            & (np.abs(local[:, 1] / z) < half)
            & (np.abs(local[:, 0] / z) < half * aspect)
        )


_NO_BODY = WorldShapes(
    np.zeros((0, 4)),
    np.zeros(1, dtype=np.intp),
    np.zeros((0, 3)),
    np.zeros(0),
    np.zeros((0, 4, 4)),
)


@numba.njit(cache=True, nogil=True)
def _lines_of_sight(
    eye: FloatArray,
    points: FloatArray,
    cells: np.ndarray,
    lower: FloatArray,
    cell: float,
    samples: int,
    near: float,
    planes: FloatArray,
    plane_start: IntArray,
    centres: FloatArray,
    radii: FloatArray,
    grow: float,
    out: FloatArray,
) -> None:
    """:func:`visibility` of each point from ``eye``, into ``out``.

    Each line has ``samples`` points from the eye to its end; those up to
    1.5 cells before the end are looked up in ``cells`` (the first occupied
    one blocks the line), and, where the line passes within a shape's grown
    bounding sphere, tested against its grown planes (the robot blocks it).
    """
    nx, ny, nz = cells.shape
    spacing = 1.0 / (samples - 1)
    for r in range(points.shape[0]):
        dx = points[r, 0] - eye[0]
        dy = points[r, 1] - eye[1]
        dz = points[r, 2] - eye[2]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        limit = length - 1.5 * cell
        blocked = False
        unseen = 0
        for j in range(samples):
            t = j * spacing
            if not t * length < limit:
                break  # the point's own cell and the one before it
            i = math.floor((eye[0] + t * dx - lower[0]) / cell)
            k = math.floor((eye[1] + t * dy - lower[1]) / cell)
            m = math.floor((eye[2] + t * dz - lower[2]) / cell)
            state = UNKNOWN
            if 0 <= i < nx and 0 <= k < ny and 0 <= m < nz:
                state = cells[i, k, m]
            if state == OCCUPIED:
                blocked = True
                break
            if state == UNKNOWN:
                unseen += 1
        # The robot: only the samples within a shape's grown sphere are asked.
        dd = dx * dx + dy * dy + dz * dz
        s = 0
        while not blocked and s < radii.size and dd > 0.0:
            ex = eye[0] - centres[s, 0]
            ey = eye[1] - centres[s, 1]
            ez = eye[2] - centres[s, 2]
            reach = radii[s] + grow
            b = ex * dx + ey * dy + ez * dz
            c = ex * ex + ey * ey + ez * ez - reach * reach
            disc = b * b - dd * c
            if disc >= 0.0:
                root = math.sqrt(disc)
                first = max(0, math.ceil((-b - root) / dd / spacing))
                last = min(samples - 1, math.floor((-b + root) / dd / spacing))
                for j in range(first, last + 1):
                    t = j * spacing
                    at = t * length
                    if not at < limit:
                        break
                    if at > near and inside_convex(
                        eye[0] + t * dx,
                        eye[1] + t * dy,
                        eye[2] + t * dz,
                        planes,
                        plane_start[s],
                        plane_start[s + 1],
                        grow,
                    ):
                        blocked = True
                        break
            s += 1
        out[r] = 0.0 if blocked else math.exp(-unseen * length * spacing / UNSEEN_DEPTH)
