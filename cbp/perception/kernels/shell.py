# SPDX-License-Identifier: Apache-2.0
"""The grid's upkeep: the robot's volume made free, the obstacles' shell indexed.

Space the robot held is free (:func:`carve_shapes`); the cells next to open
space, the only ones that can be nearest a robot shape standing in it, are
collected brick by brick, redone only where cells changed
(:func:`shell_update`), for the snapshot the collision world queries.
"""

from __future__ import annotations

import numba
import numpy as np

from cbp.collision.cell_kernels import SLOT_BRICK
from cbp.collision.geometry import inside_convex
from cbp.perception.kernels.arrays import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    GridArrays,
    SlotArray,
)
from cbp.robot import FloatArray, IntArray

__all__ = ["carve_shapes", "shell_update"]


@numba.njit(cache=True, nogil=True)
def carve_shapes(
    grid: GridArrays,
    planes: FloatArray,
    plane_start: IntArray,
    centres: FloatArray,
    radii: FloatArray,
    boxes: FloatArray,
    grow: float,
) -> int:
    """Mark unknown cells whose centre is inside a grown shape free; return count.

    The robot was there, so the space is free (occupied cells are kept: an
    obstacle seen inside the robot's padding is real). The shapes as
    :class:`~cbp.collision.geometry.WorldShapes` gives them; ``boxes``
    (shapes, 6) holds each grown shape's world bounding box (lower corner,
    upper corner). Cells and dirty bricks (``grid``) are updated in place.
    """
    lower, cell, dirty, brick = grid.lower, grid.cell, grid.dirty, grid.brick
    nx, ny, nz = grid.cells.shape
    flat = grid.cells.reshape(-1)
    size = (nx, ny, nz)
    lo = np.empty(3, dtype=np.int64)
    hi = np.empty(3, dtype=np.int64)
    changed = 0
    for s in range(boxes.shape[0]):
        for a in range(3):
            lo[a] = max(int(np.ceil((boxes[s, a] - lower[a]) / cell - 0.5)), 0)
            top = int(np.floor((boxes[s, 3 + a] - lower[a]) / cell - 0.5)) + 1
            hi[a] = min(top, size[a])
        first, last = plane_start[s], plane_start[s + 1]
        cx, cy, cz = centres[s, 0], centres[s, 1], centres[s, 2]
        reach2 = (radii[s] + grow) ** 2
        for i in range(lo[0], hi[0]):
            x = lower[0] + (i + 0.5) * cell
            for j in range(lo[1], hi[1]):
                y = lower[1] + (j + 0.5) * cell
                row = (i * ny + j) * nz
                for k in range(lo[2], hi[2]):
                    if flat[row + k] != UNKNOWN:
                        continue
                    z = lower[2] + (k + 0.5) * cell
                    if (x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2 > reach2:
                        continue
                    if inside_convex(x, y, z, planes, first, last, grow):
                        flat[row + k] = FREE
                        dirty[i // brick, j // brick, k // brick] = True
                        grid.stamp[i // brick, j // brick, k // brick] = grid.clock[0]
                        changed += 1
    return changed


@numba.njit(cache=True, nogil=True)
def shell_update(
    grid: GridArrays,
    blocked: np.ndarray,
    unknown_blocks: bool,
    old_centres: FloatArray,
    old_start: IntArray,
    old_slots: SlotArray,
) -> tuple[FloatArray, IntArray, SlotArray]:
    """The obstacle cells next to open space, brick by brick, redone where changed.

    A cell is blocked when occupied, or unknown and ``unknown_blocks``; it is in
    the shell when one of its six neighbours inside the grid is not blocked.
    Only the shell can be the cell closest to a robot shape that stands in open
    space, so only the shell is indexed: a solid block of unknown space costs
    its surface, not its volume.

    Only the bricks marked ``dirty`` (a cell in them changed state since the
    last update) have their ``blocked`` mask recomputed, and only they and
    their six neighbouring bricks (whose face cells border them) are scanned for
    the shell; every other brick's run is copied from ``old_centres``. A map
    whose view does not change costs a copy of its shell. Bricks of
    :data:`~cbp.collision.cell_kernels.SLOT_BRICK` cells also get their
    occupied places as bits (:attr:`~cbp.collision.cell_kernels.Bricks.slots`:
    the scan visits a brick's cells in place order), so the index of the
    shell does not read its centres again.

    Args:
        grid: the grid's arrays: its dirty bricks are cleared here, and each
            one's ``clear`` flag (all its cells free) set anew.
        blocked: the blocked mask (nx, ny, nz), kept up to date in place.
        unknown_blocks: unknown cells are obstacles.
        old_centres: the last update's shell (its result), brick by brick.
        old_start: its runs (bricks + 1,).
        old_slots: its places as bits (bricks,), empty for other bricks.

    Returns:
        (centres (N, 3) in brick order, start (bricks + 1,), slots (bricks,)
        or empty): brick b's cells are ``centres[start[b]:start[b + 1]]``,
        bricks numbered in C order.
    """
    cells, dirty, clear = grid.cells, grid.dirty, grid.clear
    lower, cell, brick = grid.lower, grid.cell, grid.brick
    nx, ny, nz = cells.shape
    bx, by, bz = dirty.shape
    redo = np.zeros((bx, by, bz), dtype=np.bool_)
    for p in range(bx):
        for q in range(by):
            for r in range(bz):
                if not dirty[p, q, r]:
                    continue
                free = True
                for i in range(p * brick, min((p + 1) * brick, nx)):
                    for j in range(q * brick, min((q + 1) * brick, ny)):
                        for k in range(r * brick, min((r + 1) * brick, nz)):
                            v = cells[i, j, k]
                            free = free and v == FREE
                            blocked[i, j, k] = v == OCCUPIED or (
                                unknown_blocks and v == UNKNOWN
                            )
                clear[p, q, r] = free
                redo[p, q, r] = True
                if p > 0:
                    redo[p - 1, q, r] = True
                if p + 1 < bx:
                    redo[p + 1, q, r] = True
                if q > 0:
                    redo[p, q - 1, r] = True
                if q + 1 < by:
                    redo[p, q + 1, r] = True
                if r > 0:
                    redo[p, q, r - 1] = True
                if r + 1 < bz:
                    redo[p, q, r + 1] = True
                dirty[p, q, r] = False
    # The redone bricks' shell cells first, each brick's run in ``fresh``
    # (its start in ``first``); then each brick's run from there or the old
    # shell, into an array of the exact size (the snapshot's own).
    n_bricks = bx * by * bz
    with_slots = brick == SLOT_BRICK
    slots = np.zeros(n_bricks if with_slots else 0, dtype=np.uint64)
    first = np.zeros(n_bricks + 1, dtype=np.int64)
    fresh = np.empty((1024, 3))
    count = 0
    total = 0
    b = 0
    for p in range(bx):
        for q in range(by):
            for r in range(bz):
                first[b] = count
                if not redo[p, q, r]:
                    total += old_start[b + 1] - old_start[b]
                    if with_slots:
                        slots[b] = old_slots[b]
                    b += 1
                    continue
                if len(fresh) - count < brick**3:  # room for a brick's cells
                    grown = np.empty((2 * len(fresh) + brick**3, 3))
                    grown[:count] = fresh[:count]
                    fresh = grown
                bits = np.uint64(0)
                for i in range(p * brick, min((p + 1) * brick, nx)):
                    for j in range(q * brick, min((q + 1) * brick, ny)):
                        for k in range(r * brick, min((r + 1) * brick, nz)):
                            if blocked[i, j, k] and (
                                (k > 0 and not blocked[i, j, k - 1])
                                or (k + 1 < nz and not blocked[i, j, k + 1])
                                or (j > 0 and not blocked[i, j - 1, k])
                                or (j + 1 < ny and not blocked[i, j + 1, k])
                                or (i > 0 and not blocked[i - 1, j, k])
                                or (i + 1 < nx and not blocked[i + 1, j, k])
                            ):
                                fresh[count, 0] = lower[0] + (i + 0.5) * cell
                                fresh[count, 1] = lower[1] + (j + 0.5) * cell
                                fresh[count, 2] = lower[2] + (k + 0.5) * cell
                                count += 1
                                if with_slots:  # (i, j, k) in the brick
                                    a = (i % brick * brick + j % brick) * brick
                                    place = a + k % brick
                                    bits |= np.uint64(1) << np.uint64(place)
                total += count - first[b]
                if with_slots:
                    slots[b] = bits
                b += 1
    first[n_bricks] = count
    centres = np.empty((total, 3))
    start = np.zeros(n_bricks + 1, dtype=np.int64)
    n = 0
    b = 0
    for p in range(bx):
        for q in range(by):
            for r in range(bz):
                if redo[p, q, r]:
                    run = first[b + 1] - first[b]
                    centres[n : n + run] = fresh[first[b] : first[b + 1]]
                else:
                    run = old_start[b + 1] - old_start[b]
                    centres[n : n + run] = old_centres[old_start[b] : old_start[b + 1]]
                n += run
                b += 1
                start[b] = n
    return centres, start, slots
