# SPDX-License-Identifier: Apache-2.0
"""Occupied cells indexed by brick, for queries whose cost follows the robot.

An occupancy map's cells lie on a regular grid, so they are indexed by the block
("brick") of 4 x 4 x 4 cells they fall in: a dense table over the map's bounding
box gives each brick's run of cells in one lookup, and a query reads only the
bricks near a shape's box. The cost grows with the cells near the robot, not with
the size of the map (a map spread over a very large box gets larger bricks, to
keep the table small).
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt

from cbp.collision.cell_kernels import (
    SLOT_BRICK,
    Bricks,
    metaball_normals,
    occupied_bits,
    slot_masks,
)
from cbp.robot import FloatArray, IntArray

__all__ = ["BRICK", "MAX_BRICKS", "CellIndex"]

#: Cells per brick side.
BRICK = 4
#: The brick table is kept under this many entries; larger maps get larger bricks.
MAX_BRICKS = 1 << 22


class CellIndex:
    """Occupied cell centres sorted by brick, with each brick's run of cells.

    Args:
        centres: occupied cell centres (N, 3) [m], on a grid of step ``cell``.
        cell: cell size [m].
    """

    def __init__(self, centres: FloatArray, cell: float) -> None:
        """Sort the centres by brick and build the brick table."""
        centres = np.ascontiguousarray(centres, dtype=float).reshape(-1, 3)
        self.cell = float(cell)
        lowest = centres.min(axis=0) if len(centres) else np.zeros(3)
        self.origin = lowest - 0.5 * self.cell  # a corner of the first cell
        ijk = np.floor((centres - self.origin) / self.cell).astype(np.int64)
        extent = ijk.max(axis=0) + 1 if len(centres) else np.ones(3, dtype=np.int64)
        brick = BRICK
        while np.prod(-(-extent // brick)) > MAX_BRICKS:
            brick *= 2
        self.brick = brick
        self.dims = (-(-extent // brick)).astype(np.int64)
        b = ijk // brick
        key = (b[:, 0] * self.dims[1] + b[:, 1]) * self.dims[2] + b[:, 2]
        # By brick, and within a brick by place (i, j, k) (:attr:`Bricks.slots`).
        order = np.lexsort((_places(ijk, brick), key))
        self.centres = np.ascontiguousarray(centres[order])
        """Centres sorted by brick (N, 3)."""
        counts = np.bincount(key, minlength=int(np.prod(self.dims)))
        self.start = np.zeros(counts.size + 1, dtype=np.int64)
        np.cumsum(counts, out=self.start[1:])
        self.occupied = occupied_bits(self.start, self.dims)
        """Each column's non-empty bricks, as bits (:class:`Bricks`)."""
        self.slots = _place_bits(self)

    @classmethod
    def from_bricks(
        cls,
        centres: FloatArray,
        start: IntArray,
        origin: FloatArray,
        cell: float,
        brick: int,
        dims: IntArray,
        slots: npt.NDArray[np.uint64] | None = None,
    ) -> CellIndex:
        """An index of centres already sorted by brick (a map's compiled pass).

        Args:
            centres: cell centres (N, 3), brick by brick.
            start: brick b's cells are ``centres[start[b]:start[b + 1]]``.
            origin: the corner of the grid the bricks are counted from [m].
            cell: cell size [m].
            brick: cells per brick side.
            dims: bricks along x, y and z; bricks are numbered in C order.
            slots: each brick's occupied places as bits, its cells in place
                order (:attr:`Bricks.slots`), when the pass that sorted the
                centres gave them; None: computed here.
        """
        index = cls.__new__(cls)
        index.cell = float(cell)
        index.origin = np.asarray(origin, dtype=float)
        index.brick = int(brick)
        index.dims = np.asarray(dims, dtype=np.int64)
        index.centres = np.ascontiguousarray(centres, dtype=float)
        index.start = np.ascontiguousarray(start, dtype=np.int64)
        index.occupied = occupied_bits(index.start, index.dims)
        index.slots = _place_bits(index) if slots is None else slots
        return index

    def __len__(self) -> int:
        """Number of cells."""
        return len(self.centres)

    @functools.cached_property
    def bricks(self) -> Bricks:
        """The arrays as the compiled queries read them."""
        return Bricks(
            self.centres,
            self.start,
            self.origin,
            self.cell * self.brick,
            self.dims,
            self.occupied,
            self.slots,
        )

    def metaball_normals(
        self, at: FloatArray, radius: float, normals: FloatArray
    ) -> None:
        """Point ``normals`` (k, 3) down a metaball field's gradient, in place.

        The field over the cells within ``radius`` [m] of each point of ``at``
        (:func:`metaball_normals`); a normal is kept where it has no gradient.
        ``normals`` must be a C-contiguous float array.
        """
        metaball_normals(
            self.bricks,
            np.ascontiguousarray(at, dtype=float),
            float(radius),
            normals,
        )


def _place_bits(index: CellIndex) -> np.ndarray:
    """Each brick's occupied places as bits; empty unless bricks are 4 cells.

    A brick's cells not in place order are sorted into it first (a map's
    compiled pass writes them in order). Centres given twice (two on one
    place) leave it empty: queries then read each centre.
    """
    if index.brick != SLOT_BRICK:
        return np.zeros(0, dtype=np.uint64)
    masks = np.zeros(len(index.start) - 1, dtype=np.uint64)
    if slot_masks(
        index.centres, index.start, index.origin, index.cell, index.brick, masks
    ):
        return masks
    ijk = np.floor((index.centres - index.origin) / index.cell).astype(np.int64)
    if len(np.unique(ijk, axis=0)) < len(ijk):
        return np.zeros(0, dtype=np.uint64)
    brick_of = np.repeat(np.arange(len(index.start) - 1), np.diff(index.start))
    order = np.lexsort((_places(ijk, index.brick), brick_of))
    index.centres = np.ascontiguousarray(index.centres[order])
    slot_masks(index.centres, index.start, index.origin, index.cell, index.brick, masks)
    return masks


def _places(ijk: IntArray, brick: int) -> IntArray:
    """Each cell's place in its brick, (i * brick + j) * brick + k (ijk: (N, 3))."""
    local = ijk % brick
    return (local[:, 0] * brick + local[:, 1]) * brick + local[:, 2]
