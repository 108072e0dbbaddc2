# SPDX-License-Identifier: Apache-2.0
"""Occupied cells by brick, each brick's places as bits, compiled bit helpers.

A map's cells are indexed by brick (:class:`Bricks`, built by
:class:`~cbp.collision.cell_index.CellIndex`); in bricks of
:data:`SLOT_BRICK` cells a side, a brick's 64 places are the bits of one word,
so a query tests a brick's places against a shape's box at once
(:func:`slots_in_box`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
import numpy.typing as npt
from numba.cpython.unsafe.numbers import trailing_zeros

from cbp.robot import FloatArray

__all__ = [
    "ALL_BITS",
    "SLOT_BRICK",
    "Bricks",
    "brick_range",
    "lowest_bit",
    "occupied_bits",
    "place_offsets",
    "slot_masks",
    "slots_in_box",
]

#: A word of 64 set bits.
ALL_BITS = np.uint64(0xFFFFFFFFFFFFFFFF)


class Bricks(NamedTuple):
    """Cell centres sorted by brick, with each brick's run of cells.

    Brick b's cells are ``centres[start[b]:start[b + 1]]``; bricks of side
    ``size`` [m] are counted from the corner ``origin``, ``dims`` along x, y and
    z, numbered in C order. ``occupied[x * dims[1] + y]`` has bit z % 64 of
    word z // 64 set where brick (x, y, z) holds cells
    (:func:`occupied_bits`): a query reads the few non-empty bricks of a column
    without visiting the empty ones.

    Bricks of 4 x 4 x 4 cells also have ``slots``: per brick, bit
    (i * 4 + j) * 4 + k set where its cell (i, j, k) is occupied, and its cells
    in that order (:func:`slot_masks`). A query then tests all 64 places of a
    brick against a shape's box at once (:func:`slots_in_box`) and reads no
    centre; other bricks (maps spread over very large boxes) leave it empty.
    """

    centres: FloatArray
    start: npt.NDArray[np.int64]
    origin: FloatArray
    size: float
    dims: npt.NDArray[np.int64]
    occupied: npt.NDArray[np.uint64]
    slots: npt.NDArray[np.uint64]


def occupied_bits(
    start: npt.NDArray[np.int64], dims: npt.NDArray[np.int64]
) -> npt.NDArray[np.uint64]:
    """Each column's non-empty bricks as bits (:attr:`Bricks.occupied`)."""
    nx, ny, nz = (int(n) for n in dims)
    words = -(-nz // 64)
    full = np.zeros((nx * ny, words * 64), dtype=np.uint8)
    full[:, :nz] = (np.diff(start) > 0).reshape(nx * ny, nz)
    # Bit k of a word is brick 64 w + k: little-endian bytes of packed bits.
    packed = np.packbits(full, axis=1, bitorder="little")
    return np.ascontiguousarray(packed.view("<u8").astype(np.uint64))


@numba.njit(cache=True, nogil=True, inline="always")
def lowest_bit(bits: np.uint64) -> int:
    """The index of the lowest set bit of a non-zero word (one instruction)."""
    return int(trailing_zeros(bits))  # type: ignore[call-arg]  # a numba intrinsic


#: Places in a brick of :data:`SLOT_BRICK` cells a side (one bit each).
SLOT_BRICK = 4


@numba.njit(cache=True, nogil=True)
def slot_masks(
    centres: FloatArray,
    start: npt.NDArray[np.int64],
    origin: FloatArray,
    cell: float,
    brick: int,
    masks: npt.NDArray[np.uint64],
) -> bool:
    """Each brick's occupied places as bits (:attr:`Bricks.slots`), into ``masks``.

    Returns whether every brick's cells are in place order and on distinct
    places (else the masks are not to be used; the caller sorts and retries).
    """
    for b in range(len(start) - 1):
        bits = np.uint64(0)
        previous = -1
        for k in range(start[b], start[b + 1]):
            i = math.floor((centres[k, 0] - origin[0]) / cell) % brick
            j = math.floor((centres[k, 1] - origin[1]) / cell) % brick
            m = math.floor((centres[k, 2] - origin[2]) / cell) % brick
            slot = (i * brick + j) * brick + m
            if slot <= previous:
                return False
            previous = slot
            bits |= np.uint64(1) << np.uint64(slot)
        masks[b] = bits
    return True


@numba.njit(cache=True, nogil=True)
def place_offsets(M: FloatArray, cell: float, offsets: FloatArray) -> None:
    """A brick's 64 place centres from its corner, in the frame M (4, 4) places.

    Place (i, j, k) is at ((i, j, k) + 0.5) cells along the world axes, which
    are the rows of M's rotation in that frame; written to ``offsets`` (3, 64).
    """
    for a in range(3):
        ex, ey, ez = cell * M[0, a], cell * M[1, a], cell * M[2, a]
        base = 0.5 * (ex + ey + ez)
        for i in range(SLOT_BRICK):
            along_i = base + i * ex
            for j in range(SLOT_BRICK):
                along_j = along_i + j * ey
                first = (i * SLOT_BRICK + j) * SLOT_BRICK
                for m in range(SLOT_BRICK):
                    offsets[a, first + m] = along_j + m * ez


@numba.njit(cache=True, nogil=True, inline="always")
def slots_in_box(
    x0: float,
    y0: float,
    z0: float,
    offsets: FloatArray,
    lx: float,
    ly: float,
    lz: float,
    ux: float,
    uy: float,
    uz: float,
) -> np.uint64:
    """Which of a brick's 64 places lie inside a box, as bits.

    (x0, y0, z0) is the brick's corner and ``offsets`` (3, 64) its places'
    centres from it, in the box's frame. One branch-free loop over fixed
    arrays, which the compiler vectorises.
    """
    inside = np.uint64(0)
    for slot in range(64):
        x = x0 + offsets[0, slot]
        y = y0 + offsets[1, slot]
        z = z0 + offsets[2, slot]
        hit = (x > lx) & (x < ux) & (y > ly) & (y < uy) & (z > lz) & (z < uz)
        inside |= np.uint64(hit) << np.uint64(slot)
    return inside


@numba.njit(cache=True, nogil=True)
def brick_range(
    lo: float, hi: float, origin: float, size: float, dim: int
) -> tuple[int, int]:
    """The first and last of ``dim`` bricks (``size`` from ``origin``) [lo, hi] meets.

    Clipped to [0, dim - 1] (the last is below the first when none does).
    """
    first = max(math.floor((lo - origin) / size), 0)
    last = min(math.floor((hi - origin) / size), dim - 1)
    return first, last
