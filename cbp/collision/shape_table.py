# SPDX-License-Identifier: Apache-2.0
"""Robot shapes packed for the compiled cell queries, with their face grids.

A :class:`ShapeTable` holds a robot's hulls (face planes, and a grid in each
hull's frame of the largest face at each point: see
:mod:`cbp.collision.cell_kernels`) and capsules, for one reach around them.
Tables and face grids are built once and kept (robots loaded again reuse them).
"""

from __future__ import annotations

import functools
import math
import threading
from dataclasses import dataclass

import coal
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from cbp.collision.broad import compile_broad_phase
from cbp.collision.cell_index import CellIndex
from cbp.collision.cell_kernels import (
    CAPSULE,
    EXACT_WITHIN,
    HULL,
    VALUE_UNIT,
    Candidates,
    Contacts,
    Shapes,
    candidates,
    cell_contacts_flat,
    cell_hits,
    face_grid,
    hull_excesses,
    spread_contacts,
)
from cbp.collision.geometry import LinkShape, ShapePlacements
from cbp.robot import FloatArray, IntArray

__all__ = [
    "DIRECTIONS",
    "FACE_GRID_STEP",
    "FINE_REACH",
    "CellContactQuery",
    "ShapeTable",
    "compile_kernels",
    "face_grid_step",
]

#: Face-grid step [m]: fine enough that a ridge's neighbourhood is a few mm wide.
FACE_GRID_STEP = 0.0075
#: Beyond this reach [m], face grids coarsen with the reach (:func:`face_grid_step`).
FINE_REACH = 0.1


def face_grid_step(reach: float) -> float:
    """The face grids' step for a table of ``reach`` [m].

    :data:`FACE_GRID_STEP` up to :data:`FINE_REACH`; beyond, the step grows in
    proportion, so a table built for a long reach (moving cells measured
    ahead, :mod:`cbp.perception.moving`) has about as many grid points as one
    at :data:`FINE_REACH`. A coarser grid only finds fewer candidate faces near
    a hull's edges: the excess is then a lower bound further out (a distance
    never overestimated), as everywhere beyond ``EXACT_WITHIN``.
    """
    return FACE_GRID_STEP * max(1.0, reach / FINE_REACH)


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
    def arrays(self) -> Shapes:
        """The arrays as the compiled queries read them."""
        return Shapes(
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
        )

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
            found = (list(shapes), cls.build(shapes, reach, face_grid_step(reach)))
            with _CACHE_LOCK:  # the map thread and the control loop both look
                if len(_TABLES) >= _TABLE_CACHE:
                    _TABLES.pop(next(iter(_TABLES)))
                _TABLES[key] = found
        return found[1]

    @classmethod
    def kept(cls, shapes: list[LinkShape], reach: float) -> ShapeTable | None:
        """The table :meth:`for_shapes` keeps for ``shapes`` and ``reach``, if any."""
        found = _TABLES.get((tuple(id(shape) for shape in shapes), float(reach)))
        return None if found is None else found[1]

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
                kind[s] = CAPSULE
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
            plane_start.append(plane_start[-1] + (groups[s] if kind[s] == HULL else 0))
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
        self,
        index: CellIndex,
        placements: list[pin.SE3],
        margin: float,
        exact_within: float = EXACT_WITHIN,
    ) -> Candidates:
        """The closest cell per shape and group within ``margin`` of each shape.

        Distances are to the cells' centres less half a cell (cells are cubes);
        the groups are a hull's faces and a capsule's 26 directions.

        Args:
            index: the occupied cells.
            placements: the shapes' placements in the world, in table order.
            margin: the largest distance reported [m]; with half a cell, at most
                the table's reach.
            exact_within: hull distances from this on [m] are lower bounds
                (:mod:`cbp.collision.cell_kernels`); ``inf``: all in full.

        Returns:
            The shape index (K,), the cell's centre (K, 3), the shape's outward
            unit normal toward the cell (K, 3), the distance from the shape to the
            cell (K,).
        """
        half = 0.5 * index.cell
        self.check_reach(margin, half)
        frames = _frames(placements)
        capacity = self.capacity
        out = Candidates(
            np.empty(capacity, dtype=np.intp),
            np.empty((capacity, 3)),
            np.empty((capacity, 3)),
            np.empty(capacity),
        )
        count = candidates(
            index.bricks,
            self.arrays,
            frames,
            half,
            DIRECTIONS,
            float(margin),
            float(exact_within),
            out,
        )
        return out.head(count)

    def contacts(
        self,
        index: CellIndex,
        placements: list[pin.SE3],
        margin: float,
        per_shape: int,
        cos_max: float,
        spacing2: float,
        refine: tuple[float, float] | None = None,
    ) -> Contacts:
        """The shapes' contacts with the cells, reduced and refined, in one call.

        :meth:`candidates`, then :func:`~cbp.collision.cell_kernels.cell_hits`
        and, with ``refine`` (kernel radius, offset) [m], the metaball normals
        (:func:`~cbp.collision.cell_kernels.cell_contacts`). A caller that
        queries the same cells with the same settings again and again binds
        them once (:class:`CellContactQuery`).
        """
        query = CellContactQuery(
            self, index, margin, per_shape, cos_max, spacing2, refine
        )
        return query(placements)

    def check_reach(self, margin: float, half: float) -> None:
        """Raise ValueError unless ``margin`` + ``half`` a cell is within the reach.

        The boxes and face grids cover the table's reach and no more.
        """
        if margin + half > self.reach + 1e-9:
            raise ValueError(
                f"margin {margin} + half a cell {half} exceeds the table's reach "
                f"{self.reach}"
            )

    def hull_excess(
        self, s: int, points: FloatArray, exact_within: float = math.inf
    ) -> tuple[FloatArray, IntArray]:
        """Points' excess over hull ``s``'s face planes, as queries measure it.

        Args:
            s: a hull's index in the table.
            points: points in the hull's frame, inside its grown box (n, 3);
                one outside raises ValueError.
            exact_within: from this excess on [m], the nearest grid point's face
                only, as :meth:`candidates` (default: all in full).

        Returns:
            (the excess [m] (n,), the face it is measured on (n,)).
        """
        if self.kind[s] != HULL:
            raise ValueError(f"shape {s} is not a hull")
        points = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)
        depth = np.empty(len(points))
        face = np.empty(len(points), dtype=np.intp)
        hull_excesses(self.arrays, s, points, float(exact_within), depth, face)
        return depth, face


class CellContactQuery:
    """A table's contact query against one cell index, its settings bound.

    Calling it with the shapes' placements gives :meth:`ShapeTable.contacts`;
    the arguments that do not change from query to query are checked and
    packed once (a map environment keeps one per map and settings: per query,
    the packing cost about a microsecond of the 35 the compiled pass takes).
    Holds no state between calls, so threads may share it.
    """

    __slots__ = ("_leading", "_trailing", "room")

    def __init__(
        self,
        table: ShapeTable,
        index: CellIndex,
        margin: float,
        per_shape: int,
        cos_max: float,
        spacing2: float,
        refine: tuple[float, float] | None = None,
    ) -> None:
        """Check the reach and pack the arguments (see :meth:`ShapeTable.contacts`)."""
        half = 0.5 * index.cell
        table.check_reach(margin, half)
        radius, offset = refine if refine is not None else (0.0, 0.0)
        self._leading = (*index.bricks, *table.arrays)
        self._trailing = (
            half,
            DIRECTIONS,
            float(margin),
            EXACT_WITHIN,
            int(per_shape),
            float(cos_max),
            float(spacing2),
            float(radius),
            float(offset),
            table.capacity,
        )
        #: The most contacts a query gives (``per_shape`` per shape).
        self.room = min(table.capacity, max(per_shape, 1) * len(table.kind))

    def __call__(self, placements: list[pin.SE3]) -> Contacts:
        """The contacts of the shapes at ``placements`` (table order)."""
        room = self.room
        shape = np.empty(room, dtype=np.intp)
        floats = np.empty((4, room, 3))
        return Contacts.packed(shape, floats, self.into(placements, shape, floats))

    def into(
        self, placements: list[pin.SE3], shape: IntArray, floats: FloatArray
    ) -> int:
        """Write the contacts to ``shape`` (K,) and ``floats`` (4, K, 3); count them.

        As :meth:`__call__` gives them (:meth:`Contacts.packed`'s layout);
        both C-contiguous, with room for :attr:`room` contacts.
        """
        return int(
            cell_contacts_flat(
                *self._leading, _frames(placements), *self._trailing, shape, floats
            )
        )


def _frames(placements: list[pin.SE3]) -> FloatArray:
    """The placements as homogeneous matrices (n, 4, 4)."""
    if isinstance(placements, ShapePlacements):
        return placements.homogeneous
    return np.array([M.homogeneous for M in placements]).reshape(-1, 4, 4)


#: Tables by shapes and reach, oldest first, with the shapes they were built for.
_TABLES: dict[tuple[tuple[int, ...], float], tuple[list[LinkShape], ShapeTable]] = {}
#: Enough for a run's snapshot, its planners' checks and the moving cells'
#: reaches prepared before it (:func:`cbp.perception.moving.prepare_moving_tables`).
_TABLE_CACHE = 16


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
        n = int(np.prod(dims))
        faces = np.empty(n, dtype=np.int16)
        values = np.empty(n, dtype=np.float32)
        # Compiled and without the interpreter lock: a table built in the map's
        # thread (a new reach) does not stop the control loop.
        face_grid(
            np.ascontiguousarray(shape.plane_normals_t.T, dtype=np.float32),
            np.ascontiguousarray(shape.plane_offsets, dtype=np.float32),
            np.asarray(origin, dtype=float),
            np.asarray(dims, dtype=np.int64),
            float(step),
            faces,
            values,
        )
        found = faces, values
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

    The loops of :mod:`cbp.collision.cell_kernels` and
    :mod:`cbp.collision.broad`. A first compilation takes seconds; it must not
    happen in a control loop's first query, so environments call this when a
    world takes them (:meth:`~cbp.collision.environment.Environment.prepare`).
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
    found = table.candidates(index, [pin.SE3.Identity()] * 2, 0.01)
    keep = np.empty(len(found.shape), dtype=np.intp)
    order = np.lexsort((found.distance, found.shape))
    spread_contacts(order, found.shape, found.outward, found.centre, 1, 0.9, 1e-4, keep)
    index.metaball_normals(found.centre, 0.03, np.ascontiguousarray(found.outward))
    cell_hits(found, 0.005, 1, 0.9, 1e-4)
    table.contacts(index, [pin.SE3.Identity()] * 2, 0.01, 1, 0.9, 1e-4, (0.03, 0.005))
    _COMPILED = True


_COMPILED = False
