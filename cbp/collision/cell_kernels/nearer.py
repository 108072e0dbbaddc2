# SPDX-License-Identifier: Apache-2.0
"""The planners' yes-or-no check against a map: is a shape nearer than a distance.

A map's dense obstacle grid (:class:`BlockedCells`) is searched for the first
cell of the obstacles' shell too near a robot shape, measured as the contact
queries measure cells (:mod:`cbp.collision.cell_kernels.measure`); the search
stops there (:func:`any_cell_nearer`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
import numpy.typing as npt

from cbp.collision.cell_kernels.bricks import brick_range
from cbp.collision.cell_kernels.measure import (
    CAPSULE,
    VALUE_UNIT,
    Shapes,
    hull_excess,
    shape_frame,
    world_box,
)
from cbp.robot import FloatArray, IntArray

__all__ = ["BlockedCells", "any_cell_nearer"]


class BlockedCells(NamedTuple):
    """A map's dense obstacle grid for :func:`any_cell_nearer`.

    ``solid`` marks every obstacle cell, ``shell`` those of them beside a cell
    that is not one (the obstacles' surfaces), both (nx, ny, nz); cell
    ``(i, j, k)`` is centred ``(i, j, k) + 1/2`` cells from ``corner`` [m].
    ``bricks`` marks the blocks of 4 x 4 x 4 cells that hold a shell cell
    (block ``(i, j, k) // 4``).
    """

    solid: npt.NDArray[np.bool_]
    shell: npt.NDArray[np.bool_]
    bricks: npt.NDArray[np.bool_]
    corner: FloatArray
    cell: float


@numba.njit(cache=True, nogil=True)
def any_cell_nearer(
    grid: BlockedCells,
    shapes: Shapes,
    frames: FloatArray,
    centres: FloatArray,
    nearer: float,
    order: IntArray,
) -> int:
    """The first shape found nearer than ``nearer`` to an obstacle cell's centre.

    The yes-or-no check of the planners against a map (``grid``). The shapes
    are placed by ``frames`` (S, 4, 4), and the distance is measured as
    :func:`~cbp.collision.cell_kernels.candidates` measures it (a hull's
    largest excess over the faces of the eight grid points around the centre,
    a capsule's distance to its axis less its radius), to the cells of the
    obstacles' shell; a shape whose ``centres`` (S, 3, in its own frame) lies
    in an obstacle cell is inside one. Only the shell cells in each shape's
    grown box are visited (``shapes``' reach must be at least ``nearer``), and
    the first one nearer ends the search.

    The shapes are tried in ``order`` (a permutation of their indices), and
    the one found is moved to its front: a planner's next configuration is
    most often blocked by the same shape.

    Returns:
        The shape's index, or -1 when none is that near.
    """
    solid, shell, bricks, corner, cell = grid
    (
        kind, to_frame, lower, upper, capsule, planes, plane_start,
        grid_origin, grid_dims, grid_start, faces, values, step,
    ) = shapes  # fmt: skip
    nx, ny, nz = solid.shape
    inv_step = 1.0 / step
    cutoff = (0.5 * math.sqrt(3.0) * step + nearer) / VALUE_UNIT
    M = np.empty((4, 4))
    for n in range(len(order)):
        s = order[n]
        # Inside an obstacle: the shape's centre in one of its cells.
        c = centres[s]
        for a in range(3):
            M[a, 0] = (
                frames[s, a, 0] * c[0]
                + frames[s, a, 1] * c[1]
                + frames[s, a, 2] * c[2]
                + frames[s, a, 3]
            )
        ci = math.floor((M[0, 0] - corner[0]) / cell)
        cj = math.floor((M[1, 0] - corner[1]) / cell)
        ck = math.floor((M[2, 0] - corner[2]) / cell)
        if 0 <= ci < nx and 0 <= cj < ny and 0 <= ck < nz and solid[ci, cj, ck]:
            return _to_front(order, n)
        shape_frame(frames, to_frame, s, M)
        r00, r01, r02 = M[0, 0], M[0, 1], M[0, 2]
        r10, r11, r12 = M[1, 0], M[1, 1], M[1, 2]
        r20, r21, r22 = M[2, 0], M[2, 1], M[2, 2]
        tx, ty, tz = M[0, 3], M[1, 3], M[2, 3]
        lx, ly, lz = lower[s, 0], lower[s, 1], lower[s, 2]
        ux, uy, uz = upper[s, 0], upper[s, 1], upper[s, 2]
        # The grid's cells in the world box around the shape's grown box.
        mx, my, mz, wx, wy, wz = world_box(M, lx, ly, lz, ux, uy, uz)
        i0, i1 = brick_range(mx - wx, mx + wx, corner[0], cell, nx)
        j0, j1 = brick_range(my - wy, my + wy, corner[1], cell, ny)
        k0, k1 = brick_range(mz - wz, mz + wz, corner[2], cell, nz)
        is_capsule = kind[s] == CAPSULE
        radius, half_length = capsule[s, 0], capsule[s, 1]
        hull_planes = planes[plane_start[s] : plane_start[s + 1]]
        hull_faces = faces[grid_start[s] : grid_start[s + 1]]
        hull_values = values[grid_start[s] : grid_start[s + 1]]
        gx, gy, gz = grid_origin[s, 0], grid_origin[s, 1], grid_origin[s, 2]
        gny, gnz = grid_dims[s, 1], grid_dims[s, 2]
        for bi in range(i0 >> 2, (i1 >> 2) + 1):
            for bj in range(j0 >> 2, (j1 >> 2) + 1):
                for bk in range(k0 >> 2, (k1 >> 2) + 1):
                    if not bricks[bi, bj, bk]:
                        continue  # no shell cell in these 64
                    for i in range(max(bi << 2, i0), min((bi << 2) + 4, i1 + 1)):
                        dx = corner[0] + (i + 0.5) * cell - tx
                        for j in range(max(bj << 2, j0), min((bj << 2) + 4, j1 + 1)):
                            dy = corner[1] + (j + 0.5) * cell - ty
                            for k in range(
                                max(bk << 2, k0), min((bk << 2) + 4, k1 + 1)
                            ):
                                if not shell[i, j, k]:
                                    continue
                                dz = corner[2] + (k + 0.5) * cell - tz
                                x = r00 * dx + r10 * dy + r20 * dz
                                y = r01 * dx + r11 * dy + r21 * dz
                                z = r02 * dx + r12 * dy + r22 * dz
                                if (
                                    (x < lx)
                                    | (x > ux)
                                    | (y < ly)
                                    | (y > uy)
                                    | (z < lz)
                                    | (z > uz)
                                ):
                                    continue  # beyond the reach
                                if is_capsule:
                                    on_axis = min(max(z, -half_length), half_length)
                                    w = z - on_axis
                                    depth = math.sqrt(x * x + y * y + w * w) - radius
                                else:
                                    depth, _ = hull_excess(
                                        x,
                                        y,
                                        z,
                                        hull_planes,
                                        hull_faces,
                                        hull_values,
                                        gx,
                                        gy,
                                        gz,
                                        gny,
                                        gnz,
                                        inv_step,
                                        cutoff,
                                        np.inf,
                                    )
                                if depth < nearer:
                                    return _to_front(order, n)
    return -1


@numba.njit(cache=True, nogil=True)
def _to_front(order: IntArray, n: int) -> int:
    """Move ``order[n]`` to the front of ``order``; return it."""
    s = order[n]
    for m in range(n, 0, -1):
        order[m] = order[m - 1]
    order[0] = s
    return int(s)
