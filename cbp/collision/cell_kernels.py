# SPDX-License-Identifier: Apache-2.0
"""The compiled loops of cell queries: robot shapes against occupied cells.

A hull's signed distance to a point is measured as in the k-d tree version this
replaced (``benchmarks/RESULTS.md``): the point's largest excess over the face
planes. Instead of all faces (200-500 per Panda link), a per-shape grid in the
shape's frame stores which face is largest at each grid point, and a cell is
measured against the faces of the eight grid points around it. That is exact
wherever one of those faces is the largest at the cell, which is everywhere but
within a grid step of a ridge between small faces; there the excess of a
neighbouring face is taken, a slightly smaller value (a test bounds it).

Most cells near a robot are far from it (in a perceived map of the shelf scene,
about 2,000 within the 6.5 cm margin per query, 200 within 2 cm), and those
need not be measured as finely: a cell whose excess over the face of its
nearest grid point already shows it beyond ``exact_within`` (2 cm,
:data:`EXACT_WITHIN`) keeps that excess. It is a lower bound (the largest excess
is at least any one face's), exact for 84 % of such cells and within 1 mm for
99 % on the Panda's hulls (``tests/collision/test_cells.py``), never more than
two grid steps' reach (13 mm) too near: far contacts may look nearer than they
are, never farther, and the contacts that stop the arm are measured in full.

The loops are compiled with numba (the per-cell work is a few dozen flops, which
numpy can only batch at the cost of many temporary arrays); they release the GIL.
They take their arrays grouped in named tuples: :class:`Bricks` (an index's,
:class:`~cbp.collision.cell_index.CellIndex`), :class:`Shapes` (a table's,
:class:`~cbp.collision.shape_table.ShapeTable`), :class:`Candidates` and
:class:`Contacts` (results).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
import numpy.typing as npt
from numba.cpython.unsafe.numbers import trailing_zeros

from cbp.robot import FloatArray, IntArray

__all__ = [
    "CAPSULE",
    "EXACT_WITHIN",
    "HULL",
    "SLOT_BRICK",
    "VALUE_UNIT",
    "BlockedCells",
    "Bricks",
    "Candidates",
    "Contacts",
    "Shapes",
    "any_cell_nearer",
    "candidates",
    "cell_contacts",
    "cell_contacts_flat",
    "cell_hits",
    "hull_excesses",
    "metaball_normals",
    "occupied_bits",
    "reduce_cells",
    "slot_masks",
    "spread_contacts",
]

#: Shape kinds in :attr:`Shapes.kind`.
HULL, CAPSULE = 0, 1
#: Cells nearer than this to a hull [m] are measured against the faces of all
#: eight grid points around them; farther ones, against their nearest's.
EXACT_WITHIN = 0.02
#: The unit of the face grids' values [m].
VALUE_UNIT = 1e-3
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
    brick against a shape's box at once (:func:`_slots_in_box`) and reads no
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
def _lowest_bit(bits: np.uint64) -> int:
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


@numba.njit(cache=True, nogil=True, inline="always")
def _capsule_excess(
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


@numba.njit(cache=True, nogil=True)
def _place_offsets(M: FloatArray, cell: float, offsets: FloatArray) -> None:
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
def _slots_in_box(
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


class Shapes(NamedTuple):
    """Robot shapes packed for :func:`candidates` (fields as in ShapeTable)."""

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


class Candidates(NamedTuple):
    """Cells near robot shapes.

    The shape (K,), the cell's centre (K, 3), the shape's outward unit normal
    toward it (K, 3), and the distance (K,) [m].
    """

    shape: IntArray
    centre: FloatArray
    outward: FloatArray
    distance: FloatArray

    def head(self, count: int) -> Candidates:
        """The first ``count`` candidates (views)."""
        return Candidates(
            self.shape[:count],
            self.centre[:count],
            self.outward[:count],
            self.distance[:count],
        )


class Contacts(NamedTuple):
    """Contacts with cells.

    The shape (K,), the point on its surface (K, 3), the point on the cell
    (K, 3), the unit normal from the cell toward the shape (K, 3), and the
    distance (K,) [m].
    """

    shape: IntArray
    robot: FloatArray
    obstacle: FloatArray
    normal: FloatArray
    distance: FloatArray

    @classmethod
    def room(cls, count: int) -> Contacts:
        """Uninitialised arrays for ``count`` contacts (a kernel's output)."""
        return cls(
            np.empty(count, dtype=np.intp),
            np.empty((count, 3)),
            np.empty((count, 3)),
            np.empty((count, 3)),
            np.empty(count),
        )

    @classmethod
    def packed(cls, shape: IntArray, floats: FloatArray, count: int) -> Contacts:
        """The first ``count`` contacts of :func:`cell_contacts_flat`'s output.

        Views of ``shape`` (K,) and of ``floats`` (4, K, 3): robot points,
        obstacle points and normals, then distances in ``floats[3, :, 0]``.
        """
        return cls(
            shape[:count],
            floats[0, :count],
            floats[1, :count],
            floats[2, :count],
            floats[3, :count, 0],
        )

    def head(self, count: int) -> Contacts:
        """The first ``count`` contacts (views)."""
        return Contacts(
            self.shape[:count],
            self.robot[:count],
            self.obstacle[:count],
            self.normal[:count],
            self.distance[:count],
        )


@numba.njit(cache=True, nogil=True)
def _brick_range(
    lo: float, hi: float, origin: float, size: float, dim: int
) -> tuple[int, int]:
    first = max(math.floor((lo - origin) / size), 0)
    last = min(math.floor((hi - origin) / size), dim - 1)
    return first, last


@numba.njit(cache=True, nogil=True, inline="always")
def _hull_excess(
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

    Measured as :func:`candidates` measures cells (``exact_within`` as there).
    The points must lie in the hull's grown box (``shapes.lower``, ``upper``);
    one outside raises ValueError (its grid index would be out of range).
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
        depth[k], face[k] = _hull_excess(
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
def _shape_frame(
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
def _world_box(
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


@numba.njit(cache=True, nogil=True)
def candidates(
    bricks: Bricks,
    shapes: Shapes,
    frames: FloatArray,
    half: float,
    directions: FloatArray,
    margin: float,
    exact_within: float,
    out: Candidates,
) -> int:
    """The closest cell per shape and group, within ``margin`` of each shape.

    Per shape (placed by ``frames`` (S, 4, 4)): the bricks near its box, the
    cells inside its box, each cell's distance and group (a hull's face, or the
    capsule direction of ``directions`` closest to the cell), the closest cell
    per group. Hull distances from ``exact_within`` [m] on are lower bounds
    (the module's docstring). Writes to ``out`` and returns the number written.
    """
    centres, start, origin, size, dims, occupied, slots = bricks
    has_slots = len(slots) > 0
    one = np.uint64(1)
    kind, to_frame, lower, upper, capsule = (
        shapes.kind,
        shapes.to_frame,
        shapes.lower,
        shapes.upper,
        shapes.capsule,
    )
    planes, plane_start, faces, values = (
        shapes.planes,
        shapes.plane_start,
        shapes.faces,
        shapes.values,
    )
    grid_origin, grid_dims, grid_start, step = (
        shapes.grid_origin,
        shapes.grid_dims,
        shapes.grid_start,
        shapes.step,
    )
    out_shape, out_centre, out_outward, out_distance = out
    most = len(directions)
    for s in range(len(kind)):
        most = max(most, plane_start[s + 1] - plane_start[s])
    # Per group: the distance, the outward normal and the centre of its
    # closest cell so far (the centre is kept, not read back from a cell index:
    # at the end, those reads were cache misses scattered over the map).
    best = np.full(most, np.inf)
    best_out = np.zeros((most, 6))
    touched = np.empty(most, dtype=np.int64)
    M = np.empty((4, 4))
    # A slot brick's places' centres from its corner, in a shape's frame.
    offsets = np.empty((3, SLOT_BRICK**3))
    cell = size / SLOT_BRICK
    slack = 0.5 * math.sqrt(3.0) * step  # a point's distance to its grid point
    inv_step = 1.0 / step
    count = 0
    for s in range(len(kind)):
        _shape_frame(frames, to_frame, s, M)
        r00, r01, r02 = M[0, 0], M[0, 1], M[0, 2]
        r10, r11, r12 = M[1, 0], M[1, 1], M[1, 2]
        r20, r21, r22 = M[2, 0], M[2, 1], M[2, 2]
        tx, ty, tz = M[0, 3], M[1, 3], M[2, 3]
        placed = False  # the places' offsets, for this shape (when needed)
        # How far a brick reaches from its centre along the shape's axes.
        bx_reach = 0.5 * size * (abs(r00) + abs(r10) + abs(r20))
        by_reach = 0.5 * size * (abs(r01) + abs(r11) + abs(r21))
        bz_reach = 0.5 * size * (abs(r02) + abs(r12) + abs(r22))
        # The shape's box, grown by the reach (margin + half a cell).
        lx, ly, lz = lower[s, 0], lower[s, 1], lower[s, 2]
        ux, uy, uz = upper[s, 0], upper[s, 1], upper[s, 2]
        # The bricks that overlap the world box around that box.
        mx, my, mz, wx, wy, wz = _world_box(M, lx, ly, lz, ux, uy, uz)
        bx0, bx1 = _brick_range(mx - wx, mx + wx, origin[0], size, dims[0])
        by0, by1 = _brick_range(my - wy, my + wy, origin[1], size, dims[1])
        bz0, bz1 = _brick_range(mz - wz, mz + wz, origin[2], size, dims[2])
        is_capsule = kind[s] == CAPSULE
        radius, half_length = capsule[s, 0], capsule[s, 1]
        # The hull's part of the stacked tables (empty for a capsule).
        hull_planes = planes[plane_start[s] : plane_start[s + 1]]
        hull_faces = faces[grid_start[s] : grid_start[s + 1]]
        hull_values = values[grid_start[s] : grid_start[s + 1]]
        gx, gy, gz = grid_origin[s, 0], grid_origin[s, 1], grid_origin[s, 2]
        ny, nz = grid_dims[s, 1], grid_dims[s, 2]
        # A cell is rejected when its grid point's value (a lower bound, in
        # VALUE_UNIT) shows it further than the margin even after the slack.
        cutoff = (slack + half + margin) / VALUE_UNIT
        exact = exact_within + half
        n_touched = 0
        for bx in range(bx0, bx1 + 1):
            for by in range(by0, by1 + 1):
                column = bx * dims[1] + by
                row = column * dims[2]
                # The column's non-empty bricks in [bz0, bz1], lowest first.
                for word in range(bz0 >> 6, (bz1 >> 6) + 1):
                    bits = occupied[column, word]
                    low = max(bz0 - (word << 6), 0)
                    high = min(bz1 - (word << 6), 63)
                    bits &= ALL_BITS >> np.uint64(63 - high)
                    bits &= ~((np.uint64(1) << np.uint64(low)) - np.uint64(1))
                    while bits:
                        bz = (word << 6) + _lowest_bit(bits)
                        bits &= bits - np.uint64(1)
                        b = row + bz
                        # Skip a brick that misses the box along its axes (one
                        # branch: two thirds of the bricks are skipped here).
                        dx = origin[0] + (bx + 0.5) * size - tx
                        dy = origin[1] + (by + 0.5) * size - ty
                        dz = origin[2] + (bz + 0.5) * size - tz
                        x = r00 * dx + r10 * dy + r20 * dz
                        y = r01 * dx + r11 * dy + r21 * dz
                        z = r02 * dx + r12 * dy + r22 * dz
                        if (
                            (x < lx - bx_reach)
                            | (x > ux + bx_reach)
                            | (y < ly - by_reach)
                            | (y > uy + by_reach)
                            | (z < lz - bz_reach)
                            | (z > uz + bz_reach)
                        ):
                            continue
                        if has_slots:
                            # The brick's corner in the shape's frame; its
                            # places from there, all 64 tested at once.
                            dx -= 0.5 * size
                            dy -= 0.5 * size
                            dz -= 0.5 * size
                            corner_x = dx + tx
                            corner_y = dy + ty
                            corner_z = dz + tz
                            x0 = r00 * dx + r10 * dy + r20 * dz
                            y0 = r01 * dx + r11 * dy + r21 * dz
                            z0 = r02 * dx + r12 * dy + r22 * dz
                            held = slots[b]
                            if not placed:
                                _place_offsets(M, cell, offsets)
                                placed = True
                            if (
                                (x > lx + bx_reach)
                                & (x < ux - bx_reach)
                                & (y > ly + by_reach)
                                & (y < uy - by_reach)
                                & (z > lz + bz_reach)
                                & (z < uz - bz_reach)
                            ):  # the whole brick is inside the box
                                inside = held
                            else:
                                inside = held & _slots_in_box(
                                    x0, y0, z0, offsets, lx, ly, lz, ux, uy, uz
                                )
                            while inside:
                                bit = _lowest_bit(inside)
                                inside &= inside - one
                                x = x0 + offsets[0, bit]
                                y = y0 + offsets[1, bit]
                                z = z0 + offsets[2, bit]
                                if is_capsule:
                                    depth, group, ox, oy, oz = _capsule_excess(
                                        x,
                                        y,
                                        z,
                                        radius,
                                        half_length,
                                        directions,
                                        half,
                                        margin,
                                    )
                                else:
                                    depth, group = _hull_excess(
                                        x,
                                        y,
                                        z,
                                        hull_planes,
                                        hull_faces,
                                        hull_values,
                                        gx,
                                        gy,
                                        gz,
                                        ny,
                                        nz,
                                        inv_step,
                                        cutoff,
                                        exact,
                                    )
                                if depth - half >= margin or depth >= best[group]:
                                    continue
                                if best[group] == np.inf:
                                    touched[n_touched] = group
                                    n_touched += 1
                                best[group] = depth
                                if not is_capsule:
                                    ox = hull_planes[group, 0]
                                    oy = hull_planes[group, 1]
                                    oz = hull_planes[group, 2]
                                best_out[group, 0] = ox
                                best_out[group, 1] = oy
                                best_out[group, 2] = oz
                                # The place's centre: (i, j, k) of bit
                                # (i * 4 + j) * 4 + k, from the brick's corner.
                                i, j, m = bit >> 4, (bit >> 2) & 3, bit & 3
                                best_out[group, 3] = corner_x + (i + 0.5) * cell
                                best_out[group, 4] = corner_y + (j + 0.5) * cell
                                best_out[group, 5] = corner_z + (m + 0.5) * cell
                            continue
                        # Bricks without place bits: each cell read and rotated.
                        # The measuring and keeping below repeat the lines above:
                        # as an inlined helper (which writes the kept arrays, or
                        # takes tuples of them) the pass took 2-3x as long.
                        for k in range(start[b], start[b + 1]):
                            # R^T (c - t): the cell in the shape's frame.
                            dx = centres[k, 0] - tx
                            dy = centres[k, 1] - ty
                            dz = centres[k, 2] - tz
                            x = r00 * dx + r10 * dy + r20 * dz
                            y = r01 * dx + r11 * dy + r21 * dz
                            z = r02 * dx + r12 * dy + r22 * dz
                            # One branch, not six: which cells fall inside is
                            # unpredictable, and mispredictions cost more than this.
                            if not (
                                (x > lx)
                                & (x < ux)
                                & (y > ly)
                                & (y < uy)
                                & (z > lz)
                                & (z < uz)
                            ):
                                continue
                            if is_capsule:
                                depth, group, ox, oy, oz = _capsule_excess(
                                    x,
                                    y,
                                    z,
                                    radius,
                                    half_length,
                                    directions,
                                    half,
                                    margin,
                                )
                            else:
                                depth, group = _hull_excess(
                                    x,
                                    y,
                                    z,
                                    hull_planes,
                                    hull_faces,
                                    hull_values,
                                    gx,
                                    gy,
                                    gz,
                                    ny,
                                    nz,
                                    inv_step,
                                    cutoff,
                                    exact,
                                )
                            if depth - half >= margin or depth >= best[group]:
                                continue
                            if best[group] == np.inf:
                                touched[n_touched] = group
                                n_touched += 1
                            best[group] = depth
                            if not is_capsule:
                                ox = hull_planes[group, 0]
                                oy = hull_planes[group, 1]
                                oz = hull_planes[group, 2]
                            best_out[group, 0] = ox
                            best_out[group, 1] = oy
                            best_out[group, 2] = oz
                            best_out[group, 3] = centres[k, 0]
                            best_out[group, 4] = centres[k, 1]
                            best_out[group, 5] = centres[k, 2]
        for i in range(n_touched):
            g = touched[i]
            ox, oy, oz = best_out[g, 0], best_out[g, 1], best_out[g, 2]
            out_shape[count] = s
            out_centre[count, 0] = best_out[g, 3]
            out_centre[count, 1] = best_out[g, 4]
            out_centre[count, 2] = best_out[g, 5]
            out_outward[count, 0] = r00 * ox + r01 * oy + r02 * oz
            out_outward[count, 1] = r10 * ox + r11 * oy + r12 * oz
            out_outward[count, 2] = r20 * ox + r21 * oy + r22 * oz
            out_distance[count] = best[g] - half
            count += 1
            best[g] = np.inf
    return count


@numba.njit(cache=True, nogil=True)
def metaball_normals(
    bricks: Bricks, at: FloatArray, radius: float, normals: FloatArray
) -> None:
    """Replace ``normals`` by -grad F / |grad F| at ``at`` where F has a gradient.

    F is the metaball field of :class:`~cbp.collision.environment.MetaballRefiner`
    over the cells within ``radius`` of each point.
    """
    centres, start, origin, size, dims = bricks[:5]
    r2 = radius * radius
    ranges = np.empty((3, 2), dtype=np.int64)
    for i in range(len(at)):
        for a in range(3):
            ranges[a, 0], ranges[a, 1] = _brick_range(
                at[i, a] - radius, at[i, a] + radius, origin[a], size, dims[a]
            )
        gx = gy = gz = 0.0
        for bx in range(ranges[0, 0], ranges[0, 1] + 1):
            for by in range(ranges[1, 0], ranges[1, 1] + 1):
                row = (bx * dims[1] + by) * dims[2]
                for bz in range(ranges[2, 0], ranges[2, 1] + 1):
                    b = row + bz
                    for k in range(start[b], start[b + 1]):
                        dx = at[i, 0] - centres[k, 0]
                        dy = at[i, 1] - centres[k, 1]
                        dz = at[i, 2] - centres[k, 2]
                        d2 = dx * dx + dy * dy + dz * dz
                        if d2 <= r2:
                            s = 1.0 - d2 / r2
                            w = s * s  # dF/dx = -6 s^2 (x - c) / R^2: scale later
                            gx += w * dx
                            gy += w * dy
                            gz += w * dz
        norm = math.sqrt(gx * gx + gy * gy + gz * gz)
        if norm > 1e-12:  # the normal is -grad F, along +sum s^2 (x - c)
            normals[i, 0] = gx / norm
            normals[i, 1] = gy / norm
            normals[i, 2] = gz / norm


@numba.njit(cache=True, nogil=True)
def spread_contacts(
    order: IntArray,
    shape: IntArray,
    normal: FloatArray,
    point: FloatArray,
    per_shape: int,
    cos_max: float,
    spacing2: float,
    keep: IntArray,
) -> int:
    """Keep up to ``per_shape`` contacts per shape, spread over directions.

    Contacts are visited in ``order`` (by shape, then distance); one is kept unless
    its shape has ``per_shape`` already, or a kept one of its shape has a normal
    within the angle (cosine above ``cos_max``) and a point within the spacing
    (squared distance below ``spacing2``). Writes the kept indices to ``keep``
    and returns their number.
    """
    n = 0
    first = 0  # the current shape's first entry in ``keep``
    current = -1
    for k in order:
        if shape[k] != current:
            current = shape[k]
            first = n
        if n - first >= per_shape:
            continue
        similar = False
        for i in range(first, n):
            m = keep[i]
            dot = (
                normal[k, 0] * normal[m, 0]
                + normal[k, 1] * normal[m, 1]
                + normal[k, 2] * normal[m, 2]
            )
            if dot > cos_max:
                dx = point[k, 0] - point[m, 0]
                dy = point[k, 1] - point[m, 1]
                dz = point[k, 2] - point[m, 2]
                if dx * dx + dy * dy + dz * dz < spacing2:
                    similar = True
                    break
        if not similar:
            keep[n] = k
            n += 1
    return n


def cell_hits(
    found: Candidates, half: float, per_shape: int, cos_max: float, spacing2: float
) -> Contacts:
    """Contacts from :func:`candidates`' cells, reduced per shape.

    Per shape (the candidates come shape by shape), the closest cell first, then
    the next closest unless a kept one has a normal within the angle (cosine
    above ``cos_max``) and a robot point within the spacing (squared distance
    below ``spacing2``), up to ``per_shape``: :func:`spread_contacts` on cells.

    Returns:
        The contacts by shape and then distance: the point on the shape's surface,
        the point on the cell toward the shape, the unit normal from the cell
        toward the shape.
    """
    n = len(found.shape)
    out = Contacts.room(n)
    count = reduce_cells(found, n, half, per_shape, cos_max, spacing2, out)
    return out.head(count)


#: Up to this many candidates of a shape are sorted by insertion (no allocation).
_FEW = 32


@numba.njit(cache=True, nogil=True)
def reduce_cells(
    found: Candidates,
    n: int,
    half: float,
    per_shape: int,
    cos_max: float,
    spacing2: float,
    out: Contacts,
) -> int:
    """The loop of :func:`cell_hits` over the first ``n`` candidates.

    Writes to ``out``, returns the count.
    """
    shape, centre, outward, distance = found
    out_shape, robot, obstacle, normal, out_distance = out
    keep = np.empty(max(per_shape, 1), dtype=np.int64)
    order = np.empty(n, dtype=np.int64)
    count = 0
    start = 0
    while start < n:
        end = start
        while end < n and shape[end] == shape[start]:
            end += 1
        # By distance, stable as np.lexsort (equal distances keep the
        # candidates' order); a shape has a few, sorted without allocating.
        if end - start > _FEW:
            order[: end - start] = (
                np.argsort(distance[start:end], kind="mergesort") + start
            )
        else:
            for k in range(start, end):
                i = k - start
                while i > 0 and distance[order[i - 1]] > distance[k]:
                    order[i] = order[i - 1]
                    i -= 1
                order[i] = k
        kept = 0
        for k in order[: end - start]:
            if kept >= per_shape:
                break
            reach_k = distance[k] + half
            similar = False
            for i in range(kept):
                m = keep[i]
                dot = (
                    outward[k, 0] * outward[m, 0]
                    + outward[k, 1] * outward[m, 1]
                    + outward[k, 2] * outward[m, 2]
                )
                if dot > cos_max:
                    reach_m = distance[m] + half
                    d2 = 0.0
                    for a in range(3):
                        d = (centre[k, a] - reach_k * outward[k, a]) - (
                            centre[m, a] - reach_m * outward[m, a]
                        )
                        d2 += d * d
                    if d2 < spacing2:
                        similar = True
                        break
            if similar:
                continue
            keep[kept] = k
            kept += 1
            out_shape[count] = shape[k]
            for a in range(3):
                robot[count, a] = centre[k, a] - reach_k * outward[k, a]
                obstacle[count, a] = centre[k, a] - half * outward[k, a]
                normal[count, a] = -outward[k, a]
            out_distance[count] = distance[k]
            count += 1
        start = end
    return count


@numba.njit(cache=True, nogil=True)
def cell_contacts(
    bricks: Bricks,
    shapes: Shapes,
    frames: FloatArray,
    half: float,
    directions: FloatArray,
    margin: float,
    exact_within: float,
    per_shape: int,
    cos_max: float,
    spacing2: float,
    refine_radius: float,
    refine_offset: float,
    capacity: int,
    out: Contacts,
) -> int:
    """The shapes' contacts with the cells, in one call.

    :func:`candidates` (room for ``capacity``: one per shape and group), those
    reduced into ``out`` as :func:`cell_hits` does (room for ``per_shape`` per
    shape), and, when ``refine_radius`` > 0, their normals re-estimated as
    :class:`~cbp.collision.map_environment.MetaballRefiner` does: the field of
    the cells within ``refine_radius`` [m] of the obstacle point moved
    ``refine_offset`` [m] along the normal (:func:`metaball_normals`). Returns
    the number of contacts written to ``out``.
    """
    found = Candidates(
        np.empty(capacity, dtype=np.intp),
        np.empty((capacity, 3)),
        np.empty((capacity, 3)),
        np.empty(capacity),
    )
    n = candidates(
        bricks, shapes, frames, half, directions, margin, exact_within, found
    )
    count = reduce_cells(found, n, half, per_shape, cos_max, spacing2, out)
    if refine_radius > 0.0 and count > 0:
        obstacle, normal = out.obstacle, out.normal
        at = np.empty((count, 3))
        for i in range(count):
            for a in range(3):
                at[i, a] = obstacle[i, a] + refine_offset * normal[i, a]
        metaball_normals(bricks, at, refine_radius, normal[:count])
    return count


#: Where each group of :func:`cell_contacts_flat`'s arguments ends.
_B = len(Bricks.__annotations__)
_S = _B + len(Shapes.__annotations__)
_R = _S + 11  # frames ... capacity


@numba.njit(cache=True, nogil=True)
def cell_contacts_flat(*args):  # type: ignore[no-untyped-def]
    """:func:`cell_contacts` with its named tuples' fields passed one by one.

    The arguments are the fields of the Bricks, then of the Shapes, then the
    other arguments up to ``capacity``, then the output: the shapes (K,) and
    one float array (4, K, 3) of the robot points, obstacle points, normals and
    (in ``[3, :, 0]``) distances (:meth:`Contacts.packed`). Numba's dispatcher
    types arrays in compiled code but named tuples in Python: the same call
    with named tuples costs about 2 us more, and three more arrays to allocate
    and slice about 1 us.
    """
    shape, floats = args[_R:]
    return cell_contacts(  # type: ignore[call-arg]  # a tuple of known length
        Bricks(*args[:_B]),
        Shapes(*args[_B:_S]),
        *args[_S:_R],
        Contacts(shape, floats[0], floats[1], floats[2], floats[3][:, 0]),
    )


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
    :func:`candidates` measures it (a hull's largest excess over the faces of
    the eight grid points around the centre, a capsule's distance to its axis
    less its radius), to the cells of the obstacles' shell; a shape whose
    ``centres`` (S, 3, in its own frame) lies in an obstacle cell is inside
    one. Only the shell cells in each shape's grown box are visited
    (``shapes``' reach must be at least ``nearer``), and the first one nearer
    ends the search.

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
        _shape_frame(frames, to_frame, s, M)
        r00, r01, r02 = M[0, 0], M[0, 1], M[0, 2]
        r10, r11, r12 = M[1, 0], M[1, 1], M[1, 2]
        r20, r21, r22 = M[2, 0], M[2, 1], M[2, 2]
        tx, ty, tz = M[0, 3], M[1, 3], M[2, 3]
        lx, ly, lz = lower[s, 0], lower[s, 1], lower[s, 2]
        ux, uy, uz = upper[s, 0], upper[s, 1], upper[s, 2]
        # The grid's cells in the world box around the shape's grown box.
        mx, my, mz, wx, wy, wz = _world_box(M, lx, ly, lz, ux, uy, uz)
        i0, i1 = _brick_range(mx - wx, mx + wx, corner[0], cell, nx)
        j0, j1 = _brick_range(my - wy, my + wy, corner[1], cell, ny)
        k0, k1 = _brick_range(mz - wz, mz + wz, corner[2], cell, nz)
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
                                    depth, _ = _hull_excess(
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
