# SPDX-License-Identifier: Apache-2.0
"""Occupied cells against robot shapes: a brick index and compiled queries.

An occupancy map's cells lie on a regular grid, so they are indexed by the block
("brick") of 4 x 4 x 4 cells they fall in: a dense table over the map's bounding
box gives each brick's run of cells in one lookup, and a query reads only the
bricks near a shape's box. The cost grows with the cells near the robot, not with
the size of the map (a map spread over a very large box gets larger bricks, to
keep the table small).

A hull's signed distance to a point is measured as in the k-d tree version this
replaces (``benchmarks/RESULTS.md``): the point's largest excess over the face
planes. Instead of all faces (200-500 per Panda link), a per-shape grid in the
shape's frame stores which face is largest at each grid point, and a cell is
measured against the faces of the eight grid points around it. That is exact
wherever one of those faces is the largest at the cell, which is everywhere but
within a grid step of a ridge between small faces; there the excess of a
neighbouring face is taken, a slightly smaller value (a test bounds it).

The loops are compiled with numba (the per-cell work is a few dozen flops, which
numpy can only batch at the cost of many temporary arrays); they release the GIL.
"""

from __future__ import annotations

import functools
import math
import threading
from dataclasses import dataclass

import coal
import numba
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from cbp.collision.broad import compile_broad_phase
from cbp.collision.geometry import LinkShape, ShapePlacements
from cbp.robot import FloatArray, IntArray

__all__ = [
    "CellIndex",
    "ShapeTable",
    "compile_kernels",
    "metaball_normals",
    "spread_contacts",
]

#: Cells per brick side.
BRICK = 4
#: The brick table is kept under this many entries; larger maps get larger bricks.
MAX_BRICKS = 1 << 22
#: Face-grid step [m]: fine enough that a ridge's neighbourhood is a few mm wide.
FACE_GRID_STEP = 0.0075

_HULL, _CAPSULE = 0, 1
#: Guards the module's caches of face grids and shape tables.
_CACHE_LOCK = threading.Lock()

#: Directions that group a capsule's contacts: the 26 of a 3x3x3 grid's cells.
DIRECTIONS = np.array(
    [
        (x, y, z)
        for x in (-1, 0, 1)
        for y in (-1, 0, 1)
        for z in (-1, 0, 1)
        if (x, y, z) != (0, 0, 0)
    ],
    dtype=float,
)


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
        order = np.argsort(key, kind="stable")
        self.centres = np.ascontiguousarray(centres[order])
        """Centres sorted by brick (N, 3)."""
        counts = np.bincount(key, minlength=int(np.prod(self.dims)))
        self.start = np.zeros(counts.size + 1, dtype=np.int64)
        np.cumsum(counts, out=self.start[1:])

    @classmethod
    def from_bricks(
        cls,
        centres: FloatArray,
        start: IntArray,
        origin: FloatArray,
        cell: float,
        brick: int,
        dims: IntArray,
    ) -> CellIndex:
        """An index of centres already sorted by brick (a map's compiled pass).

        Args:
            centres: cell centres (N, 3), brick by brick.
            start: brick b's cells are ``centres[start[b]:start[b + 1]]``.
            origin: the corner of the grid the bricks are counted from [m].
            cell: cell size [m].
            brick: cells per brick side.
            dims: bricks along x, y and z; bricks are numbered in C order.
        """
        index = cls.__new__(cls)
        index.cell = float(cell)
        index.origin = np.asarray(origin, dtype=float)
        index.brick = int(brick)
        index.dims = np.asarray(dims, dtype=np.int64)
        index.centres = np.ascontiguousarray(centres, dtype=float)
        index.start = np.ascontiguousarray(start, dtype=np.int64)
        return index

    def __len__(self) -> int:
        """Number of cells."""
        return len(self.centres)

    def metaball_normals(
        self, at: FloatArray, radius: float, normals: FloatArray
    ) -> None:
        """Point ``normals`` (k, 3) down a metaball field's gradient, in place.

        The field over the cells within ``radius`` [m] of each point of ``at``
        (:func:`metaball_normals`); a normal is kept where it has no gradient.
        ``normals`` must be a C-contiguous float array.
        """
        metaball_normals(
            self.centres,
            self.start,
            self.origin,
            self.cell * self.brick,
            self.dims,
            np.ascontiguousarray(at, dtype=float),
            float(radius),
            normals,
        )


@dataclass(frozen=True)
class ShapeTable:
    """Robot shapes packed for the compiled query, for one reach around them.

    Attributes:
        kind: 0 for a hull (face planes), 1 for a capsule, per shape.
        to_frame: the transform from a shape's placement to the frame its planes
            and box are given in (4, 4) per shape: the inverse of the shape's
            placement on its link for hulls, identity for capsules.
        lower: the box around the shape grown by the reach, in that frame.
        upper: its opposite corner.
        capsule: (radius, half length) of capsules, zeros for hulls.
        planes: all hulls' planes (n, d), stacked; ``plane_start`` delimits them.
        plane_start: each shape's first plane, and the total at the end.
        grid_origin: the corner of each hull's face grid, in its frame.
        grid_dims: the face grid's points per axis.
        grid_start: each shape's first entry in ``faces``.
        faces: the index (within its hull) of the largest face at each grid point.
        values: that face's excess at the grid point in whole ``VALUE_UNIT``
            (1 mm), rounded down and clipped to [0, 255]: a lower bound that
            rejects the cells far outside a hull with one byte read (the grids
            of an arm's hulls then fit a core's cache).
        groups: contact groups per shape (faces, or 26 directions for capsules).
        reach: the distance the boxes are grown by [m]: a query's margin plus
            half a cell.
        step: the face grids' step [m].
    """

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
    groups: npt.NDArray[np.int64]
    reach: float
    step: float

    @functools.cached_property
    def capacity(self) -> int:
        """The most candidates a query can return: one per shape and group."""
        return int(self.groups.sum())

    @classmethod
    def for_shapes(cls, shapes: list[LinkShape], reach: float) -> ShapeTable:
        """The table of ``shapes`` for ``reach``, built once and kept.

        A few tables are kept, with their shapes (so the key, the shapes'
        identities, cannot be reused by other objects while a table is kept).
        """
        key = (tuple(id(shape) for shape in shapes), float(reach))
        found = _TABLES.get(key)
        if found is None:
            found = (list(shapes), cls.build(shapes, reach))
            with _CACHE_LOCK:  # the map thread and the control loop both look
                if len(_TABLES) >= _TABLE_CACHE:
                    _TABLES.pop(next(iter(_TABLES)))
                _TABLES[key] = found
        return found[1]

    @classmethod
    def build(
        cls, shapes: list[LinkShape], reach: float, step: float = FACE_GRID_STEP
    ) -> ShapeTable:
        """Pack ``shapes`` for queries up to ``reach`` from their surface."""
        n = len(shapes)
        kind = np.zeros(n, dtype=np.int64)
        to_frame = np.tile(np.eye(4), (n, 1, 1))
        lower, upper = np.zeros((n, 3)), np.zeros((n, 3))
        capsule = np.zeros((n, 2))
        planes, plane_start = [], [0]
        grid_origin, grid_dims = np.zeros((n, 3)), np.ones((n, 3), dtype=np.int64)
        faces, values, grid_start = [], [], [0]
        groups = np.zeros(n, dtype=np.int64)
        for s, shape in enumerate(shapes):
            geometry = shape.shape
            if isinstance(geometry, coal.Capsule):
                kind[s] = _CAPSULE
                r, h = float(geometry.radius), float(geometry.halfLength)
                capsule[s] = r, h
                lower[s], upper[s] = (-r, -r, -h - r), (r, r, h + r)
                groups[s] = len(DIRECTIONS)
                grid, value = np.zeros(1, dtype=np.int16), np.zeros(1, np.uint8)
            else:
                if len(shape.planes) > np.iinfo(np.int16).max:
                    raise ValueError(
                        f"{shape.name}: a hull of {len(shape.planes)} faces; the "
                        f"face grids index at most {np.iinfo(np.int16).max}"
                    )
                to_frame[s] = shape.placement.inverse().homogeneous
                lower[s], upper[s] = shape.lower, shape.upper
                planes.append(shape.planes)
                groups[s] = len(shape.planes)
                grid_origin[s] = lower[s] - reach - step
                grid_dims[s] = np.ceil((upper[s] - lower[s] + 2 * reach) / step) + 3
                grid, excess = _largest_faces(shape, grid_origin[s], grid_dims[s], step)
                value = np.clip(np.floor(excess / VALUE_UNIT), 0, 255).astype(np.uint8)
            lower[s] -= reach
            upper[s] += reach
            plane_start.append(plane_start[-1] + (groups[s] if kind[s] == _HULL else 0))
            faces.append(grid)
            values.append(value)
            grid_start.append(grid_start[-1] + grid.size)
        return cls(
            kind=kind,
            to_frame=to_frame,
            lower=lower,
            upper=upper,
            capsule=capsule,
            planes=np.ascontiguousarray(
                np.concatenate(planes) if planes else np.zeros((0, 4))
            ),
            plane_start=np.array(plane_start, dtype=np.int64),
            grid_origin=grid_origin,
            grid_dims=grid_dims,
            grid_start=np.array(grid_start, dtype=np.int64),
            faces=np.concatenate(faces),
            values=np.concatenate(values),
            groups=groups,
            reach=float(reach),
            step=float(step),
        )

    def candidates(
        self, index: CellIndex, placements: list[pin.SE3], margin: float
    ) -> tuple[IntArray, FloatArray, FloatArray, FloatArray]:
        """The closest cell per shape and group within ``margin`` of each shape.

        Distances are to the cells' centres less half a cell (cells are cubes);
        the groups are a hull's faces and a capsule's 26 directions.

        Args:
            index: the occupied cells.
            placements: the shapes' placements in the world, in table order.
            margin: the largest distance reported [m]; with half a cell, at most
                the table's reach.

        Returns:
            (shape index (K,), cell centre (K, 3), outward unit normal of the shape
            toward the cell (K, 3), distance from the shape to the cell (K,)).
        """
        half = 0.5 * index.cell
        if margin + half > self.reach + 1e-9:
            raise ValueError(
                f"margin {margin} + half a cell {half} exceeds the table's reach "
                f"{self.reach}"
            )
        frames = (
            placements.homogeneous
            if isinstance(placements, ShapePlacements)
            else np.array([M.homogeneous for M in placements]).reshape(-1, 4, 4)
        )
        capacity = self.capacity
        shape = np.empty(capacity, dtype=np.intp)
        centre = np.empty((capacity, 3))
        outward = np.empty((capacity, 3))
        distance = np.empty(capacity)
        count = _candidates(
            index.centres,
            index.start,
            index.origin,
            index.cell * index.brick,
            index.dims,
            half,
            frames,
            self.kind,
            self.to_frame,
            self.lower,
            self.upper,
            self.capsule,
            self.planes,
            self.plane_start,
            self.grid_origin,
            self.grid_dims,
            self.grid_start,
            self.faces,
            self.values,
            self.step,
            DIRECTIONS,
            float(margin),
            shape,
            centre,
            outward,
            distance,
        )
        return shape[:count], centre[:count], outward[:count], distance[:count]

    def hull_excess(self, s: int, points: FloatArray) -> tuple[FloatArray, IntArray]:
        """Points' excess over hull ``s``'s face planes, as queries measure it.

        Args:
            s: a hull's index in the table.
            points: points in the hull's frame, inside its grown box (n, 3).

        Returns:
            (the excess [m] (n,), the face it is measured on (n,)).
        """
        if self.kind[s] != _HULL:
            raise ValueError(f"shape {s} is not a hull")
        points = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)
        depth = np.empty(len(points))
        face = np.empty(len(points), dtype=np.intp)
        planes = slice(self.plane_start[s], self.plane_start[s + 1])
        grid = slice(self.grid_start[s], self.grid_start[s + 1])
        _hull_excesses(
            points,
            self.planes[planes],
            self.faces[grid],
            self.values[grid],
            self.grid_origin[s],
            self.grid_dims[s],
            1.0 / self.step,
            depth,
            face,
        )
        return depth, face


#: The unit of the face grids' values [m].
VALUE_UNIT = 1e-3

#: Tables by shapes and reach, oldest first, with the shapes they were built for.
_TABLES: dict[tuple[tuple[int, ...], float], tuple[list[LinkShape], ShapeTable]] = {}
_TABLE_CACHE = 8


def _largest_faces(
    shape: LinkShape, origin: FloatArray, dims: npt.NDArray[np.int64], step: float
) -> tuple[npt.NDArray[np.int16], npt.NDArray[np.float32]]:
    """The largest face's index and excess at every point of a grid (x major).

    Cached by the hull and the grid: robots loaded again reuse their grids.
    """
    key = (
        shape.planes.tobytes(),
        origin.tobytes(),
        dims.tobytes(),
        float(step),
    )
    found = _FACE_GRIDS.get(key)
    if found is None:
        axes = [origin[k] + step * np.arange(dims[k]) for k in range(3)]
        yz = np.stack(np.meshgrid(axes[1], axes[2], indexing="ij"), -1).reshape(-1, 2)
        faces = np.empty((int(dims[0]), len(yz)), dtype=np.int16)
        values = np.empty((int(dims[0]), len(yz)), dtype=np.float32)
        points = np.empty((len(yz), 3), dtype=np.float32)
        points[:, 1:] = yz
        rows = np.arange(len(yz))
        for i, x in enumerate(axes[0]):  # one slab at a time: bounded memory
            points[:, 0] = x
            excess = points.dot(shape.plane_normals_t) - shape.plane_offsets
            faces[i] = excess.argmax(axis=1)
            values[i] = excess[rows, faces[i]]
        found = faces.reshape(-1), values.reshape(-1)
        with _CACHE_LOCK:
            if len(_FACE_GRIDS) >= _FACE_GRID_CACHE:
                _FACE_GRIDS.pop(next(iter(_FACE_GRIDS)))
            _FACE_GRIDS[key] = found
    return found


#: Face grids by hull and grid, oldest first.
_FACE_GRIDS: dict[
    tuple[bytes, bytes, bytes, float],
    tuple[npt.NDArray[np.int16], npt.NDArray[np.float32]],
] = {}
_FACE_GRID_CACHE = 64


def compile_kernels() -> None:
    """Compile the loops, or load them from numba's cache, once per process.

    The loops here and in :mod:`cbp.collision.broad`. A first compilation takes
    seconds; it must not happen in a control loop's first query, so environments
    call this when a world takes them
    (:meth:`~cbp.collision.environment.Environment.prepare`).
    """
    global _COMPILED
    if _COMPILED:
        return
    compile_broad_phase()
    probes = [
        LinkShape.probe("box", coal.Box(0.1, 0.1, 0.1)),
        LinkShape.probe("capsule", coal.Capsule(0.05, 0.1)),
    ]
    table = ShapeTable.build(probes, 0.02, step=0.01)
    index = CellIndex(np.array([[0.0, 0.0, 0.06], [0.0, 0.0, -0.06]]), 0.01)
    shape, centre, outward, distance = table.candidates(
        index, [pin.SE3.Identity()] * 2, 0.01
    )
    keep = np.empty(len(shape), dtype=np.intp)
    spread_contacts(
        np.lexsort((distance, shape)), shape, outward, centre, 1, 0.9, 1e-4, keep
    )
    index.metaball_normals(centre, 0.03, np.ascontiguousarray(outward))
    cell_hits(shape, centre, outward, distance, 0.005, 1, 0.9, 1e-4)
    _COMPILED = True


_COMPILED = False


# ------------------------------------------------------------------ compiled loops


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
    last: tuple[int, int, int],
    inv_step: float,
    cutoff: float,
) -> tuple[float, int]:
    """A point's excess over a hull's faces (in its frame), and the face.

    ``planes``, ``faces`` and ``values`` are the hull's; its grid starts at
    (gx, gy, gz) with ``ny`` x ``nz`` points per x slab, and ``last`` the largest
    first index of a grid cell per axis. The excess is the largest over the faces
    stored at the eight grid points around the point; it is ``inf`` (face -1)
    when the nearest grid point's value shows the excess is at least ``cutoff``
    (both in ``VALUE_UNIT``) less the distance to that point (the excess changes
    by at most the distance moved).
    """
    fx = (x - gx) * inv_step
    fy = (y - gy) * inv_step
    fz = (z - gz) * inv_step
    # The nearest grid point first: most cells stop there.
    near = (
        min(max(int(fx + 0.5), 0), last[0] + 1) * ny
        + min(max(int(fy + 0.5), 0), last[1] + 1)
    ) * nz + min(max(int(fz + 0.5), 0), last[2] + 1)
    if values[near] >= cutoff:  # in VALUE_UNIT
        return np.inf, -1
    ix = min(max(int(fx), 0), last[0])
    iy = min(max(int(fy), 0), last[1])
    iz = min(max(int(fz), 0), last[2])
    depth = -np.inf
    face = 0
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
def _hull_excesses(
    points: FloatArray,
    planes: FloatArray,
    faces: npt.NDArray[np.int16],
    values: npt.NDArray[np.uint8],
    origin: FloatArray,
    dims: npt.NDArray[np.int64],
    inv_step: float,
    depth: FloatArray,
    face: IntArray,
) -> None:
    last = (dims[0] - 2, dims[1] - 2, dims[2] - 2)
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
            last,
            inv_step,
            np.inf,
        )


@numba.njit(cache=True, nogil=True)
def _candidates(
    centres: FloatArray,
    start: npt.NDArray[np.int64],
    origin: FloatArray,
    size: float,
    dims: npt.NDArray[np.int64],
    half: float,
    frames: FloatArray,
    kind: npt.NDArray[np.int64],
    to_frame: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    capsule: FloatArray,
    planes: FloatArray,
    plane_start: npt.NDArray[np.int64],
    grid_origin: FloatArray,
    grid_dims: npt.NDArray[np.int64],
    grid_start: npt.NDArray[np.int64],
    faces: npt.NDArray[np.int16],
    values: npt.NDArray[np.uint8],
    step: float,
    directions: FloatArray,
    margin: float,
    out_shape: IntArray,
    out_centre: FloatArray,
    out_outward: FloatArray,
    out_distance: FloatArray,
) -> int:
    """The pass of :meth:`ShapeTable.candidates`, on the unpacked arrays.

    Per shape: the bricks near its box, the cells inside its box, each cell's
    distance and group, the closest cell per group; returns the number written.
    """
    most = len(directions)
    for s in range(len(kind)):
        most = max(most, plane_start[s + 1] - plane_start[s])
    best = np.full(most, np.inf)
    best_cell = np.full(most, -1, dtype=np.int64)
    best_out = np.zeros((most, 3))
    touched = np.empty(most, dtype=np.int64)
    M = np.empty((4, 4))
    brick_radius = 0.5 * math.sqrt(3.0) * size
    slack = 0.5 * math.sqrt(3.0) * step  # a point's distance to its grid point
    inv_step = 1.0 / step
    count = 0
    for s in range(len(kind)):
        # The shape's frame in the world: placement x to_frame.
        for i in range(4):
            for j in range(4):
                M[i, j] = (
                    frames[s, i, 0] * to_frame[s, 0, j]
                    + frames[s, i, 1] * to_frame[s, 1, j]
                    + frames[s, i, 2] * to_frame[s, 2, j]
                    + frames[s, i, 3] * to_frame[s, 3, j]
                )
        r00, r01, r02 = M[0, 0], M[0, 1], M[0, 2]
        r10, r11, r12 = M[1, 0], M[1, 1], M[1, 2]
        r20, r21, r22 = M[2, 0], M[2, 1], M[2, 2]
        tx, ty, tz = M[0, 3], M[1, 3], M[2, 3]
        # The shape's box, grown by the reach (margin + half a cell).
        lx, ly, lz = lower[s, 0], lower[s, 1], lower[s, 2]
        ux, uy, uz = upper[s, 0], upper[s, 1], upper[s, 2]
        # The bricks that overlap the world box around that box.
        cx, cy, cz = 0.5 * (lx + ux), 0.5 * (ly + uy), 0.5 * (lz + uz)
        ex, ey, ez = 0.5 * (ux - lx), 0.5 * (uy - ly), 0.5 * (uz - lz)
        mx = r00 * cx + r01 * cy + r02 * cz + tx
        my = r10 * cx + r11 * cy + r12 * cz + ty
        mz = r20 * cx + r21 * cy + r22 * cz + tz
        wx = abs(r00) * ex + abs(r01) * ey + abs(r02) * ez
        wy = abs(r10) * ex + abs(r11) * ey + abs(r12) * ez
        wz = abs(r20) * ex + abs(r21) * ey + abs(r22) * ez
        bx0, bx1 = _brick_range(mx - wx, mx + wx, origin[0], size, dims[0])
        by0, by1 = _brick_range(my - wy, my + wy, origin[1], size, dims[1])
        bz0, bz1 = _brick_range(mz - wz, mz + wz, origin[2], size, dims[2])
        is_capsule = kind[s] == _CAPSULE
        radius, half_length = capsule[s, 0], capsule[s, 1]
        p0 = plane_start[s]
        # The hull's part of the stacked tables (empty for a capsule).
        hull_planes = planes[p0 : plane_start[s + 1]]
        hull_faces = faces[grid_start[s] : grid_start[s + 1]]
        hull_values = values[grid_start[s] : grid_start[s + 1]]
        gx, gy, gz = grid_origin[s, 0], grid_origin[s, 1], grid_origin[s, 2]
        ny, nz = grid_dims[s, 1], grid_dims[s, 2]
        last = (grid_dims[s, 0] - 2, ny - 2, nz - 2)  # a grid cell's first point
        # A cell is rejected when its grid point's value (a lower bound, in
        # VALUE_UNIT) shows it further than the margin even after the slack.
        cutoff = (slack + half + margin) / VALUE_UNIT
        n_touched = 0
        for bx in range(bx0, bx1 + 1):
            for by in range(by0, by1 + 1):
                row = (bx * dims[1] + by) * dims[2]
                for bz in range(bz0, bz1 + 1):
                    b = row + bz
                    if start[b] == start[b + 1]:
                        continue
                    # Skip a brick whose bounding sphere misses the box.
                    dx = origin[0] + (bx + 0.5) * size - tx
                    dy = origin[1] + (by + 0.5) * size - ty
                    dz = origin[2] + (bz + 0.5) * size - tz
                    x = r00 * dx + r10 * dy + r20 * dz
                    y = r01 * dx + r11 * dy + r21 * dz
                    z = r02 * dx + r12 * dy + r22 * dz
                    if (
                        x < lx - brick_radius
                        or x > ux + brick_radius
                        or y < ly - brick_radius
                        or y > uy + brick_radius
                        or z < lz - brick_radius
                        or z > uz + brick_radius
                    ):
                        continue
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
                            on_axis = min(max(z, -half_length), half_length)
                            ox, oy, oz = x, y, z - on_axis
                            length = math.sqrt(ox * ox + oy * oy + oz * oz)
                            if length < 1e-12:  # on the axis: take x
                                ox, oy, oz, length = 1.0, 0.0, 0.0, 1.0
                            depth = length - radius
                            if depth - half >= margin:
                                continue
                            ox, oy, oz = ox / length, oy / length, oz / length
                            group = 0
                            top = -np.inf
                            for g in range(len(directions)):
                                v = (
                                    directions[g, 0] * ox
                                    + directions[g, 1] * oy
                                    + directions[g, 2] * oz
                                )
                                if v > top:
                                    top, group = v, g
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
                                last,
                                inv_step,
                                cutoff,
                            )
                            if depth - half >= margin:
                                continue
                            ox = hull_planes[group, 0]
                            oy = hull_planes[group, 1]
                            oz = hull_planes[group, 2]
                        if depth < best[group]:
                            if best_cell[group] < 0:
                                touched[n_touched] = group
                                n_touched += 1
                            best[group] = depth
                            best_cell[group] = k
                            best_out[group, 0] = ox
                            best_out[group, 1] = oy
                            best_out[group, 2] = oz
        for i in range(n_touched):
            g = touched[i]
            k = best_cell[g]
            ox, oy, oz = best_out[g, 0], best_out[g, 1], best_out[g, 2]
            out_shape[count] = s
            out_centre[count, 0] = centres[k, 0]
            out_centre[count, 1] = centres[k, 1]
            out_centre[count, 2] = centres[k, 2]
            out_outward[count, 0] = r00 * ox + r01 * oy + r02 * oz
            out_outward[count, 1] = r10 * ox + r11 * oy + r12 * oz
            out_outward[count, 2] = r20 * ox + r21 * oy + r22 * oz
            out_distance[count] = best[g] - half
            count += 1
            best[g] = np.inf
            best_cell[g] = -1
    return count


@numba.njit(cache=True, nogil=True)
def metaball_normals(
    centres: FloatArray,
    start: npt.NDArray[np.int64],
    origin: FloatArray,
    size: float,
    dims: npt.NDArray[np.int64],
    at: FloatArray,
    radius: float,
    normals: FloatArray,
) -> None:
    """Replace ``normals`` by -grad F / |grad F| at ``at`` where F has a gradient.

    F is the metaball field of :class:`~cbp.collision.environment.MetaballRefiner`
    over the cells within ``radius`` of each point.
    """
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
    shape: IntArray,
    centre: FloatArray,
    outward: FloatArray,
    distance: FloatArray,
    half: float,
    per_shape: int,
    cos_max: float,
    spacing2: float,
) -> tuple[IntArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Contacts from :meth:`ShapeTable.candidates`' cells, reduced per shape.

    Per shape (the candidates come shape by shape), the closest cell first, then
    the next closest unless a kept one has a normal within the angle (cosine
    above ``cos_max``) and a robot point within the spacing (squared distance
    below ``spacing2``), up to ``per_shape``: :func:`spread_contacts` on cells.

    Returns:
        (shape, point on the shape's surface, point on the cell toward the
        shape, unit normal from the cell toward the shape, distance), by shape
        and then distance.
    """
    n = len(shape)
    out_shape = np.empty(n, dtype=np.intp)
    robot, obstacle, normal = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    out_distance = np.empty(n)
    count = _cell_hits(
        shape,
        centre,
        outward,
        distance,
        half,
        per_shape,
        cos_max,
        spacing2,
        out_shape,
        robot,
        obstacle,
        normal,
        out_distance,
    )
    return (
        out_shape[:count],
        robot[:count],
        obstacle[:count],
        normal[:count],
        out_distance[:count],
    )


@numba.njit(cache=True, nogil=True)
def _cell_hits(
    shape: IntArray,
    centre: FloatArray,
    outward: FloatArray,
    distance: FloatArray,
    half: float,
    per_shape: int,
    cos_max: float,
    spacing2: float,
    out_shape: IntArray,
    robot: FloatArray,
    obstacle: FloatArray,
    normal: FloatArray,
    out_distance: FloatArray,
) -> int:
    """The loop of :func:`cell_hits`; returns the number of contacts written."""
    n = shape.size
    keep = np.empty(max(per_shape, 1), dtype=np.int64)
    count = 0
    start = 0
    while start < n:
        end = start
        while end < n and shape[end] == shape[start]:
            end += 1
        # Stable, as np.lexsort: equal distances keep the candidates' order.
        order = np.argsort(distance[start:end], kind="mergesort") + start
        kept = 0
        for k in order:
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
