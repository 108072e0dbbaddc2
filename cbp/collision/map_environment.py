# SPDX-License-Identifier: Apache-2.0
"""An occupancy map as an environment: occupied cells indexed by brick.

Queries measure cells against the robot's shapes in one compiled pass
(:mod:`cbp.collision.cell_kernels`); planners' yes-or-no checks use a coal
octree of the same cells.
"""

from __future__ import annotations

import copy
import functools
import math
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
from scipy.spatial import cKDTree

from cbp.collision.broad import shape_bounds
from cbp.collision.cell_index import CellIndex
from cbp.collision.contacts import ContactSet
from cbp.collision.convex_kernels import contact_buffers, self_contacts
from cbp.collision.environment import Environment, NarrowPhase, WholeQuery
from cbp.collision.geometry import LinkShape, PlacedShapes, ShapePlacements
from cbp.collision.shape_table import CellContactQuery, ShapeTable, compile_kernels
from cbp.robot import FloatArray, IntArray

__all__ = ["BlockedGrid", "MetaballRefiner", "OccupancyEnvironment"]


@dataclass(frozen=True)
class BlockedGrid:
    """Which cells of a dense grid are obstacles: occupied, or unknown and counted so.

    Attributes:
        mask: True for obstacle cells, (nx, ny, nz).
        lower: the grid's lower corner [m].
        cell: cell size [m].
        outside: whether space outside the grid is an obstacle (a map's: it is
            unknown, and so counted when unknown space is).
    """

    mask: np.ndarray
    lower: FloatArray
    cell: float
    outside: bool = False

    def contains(self, points: FloatArray) -> np.ndarray:
        """Which points (n, 3) lie in an obstacle cell (outside the grid: outside)."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        idx = np.floor((points - self.lower) / self.cell).astype(np.intp)
        inside = np.all((idx >= 0) & (idx < np.array(self.mask.shape)), axis=1)
        out = np.full(len(points), self.outside, dtype=bool)
        i = idx[inside]
        out[inside] = self.mask[i[:, 0], i[:, 1], i[:, 2]]
        return out


@dataclass(frozen=True, kw_only=True)
class MetaballRefiner:
    r"""Re-estimate a contact normal from a metaball surface over occupied cells.

    The field :math:`F(x) = \sum_i (1 - \|x - c_i\|^2 / R^2)^3` over the centres
    :math:`c_i` within :math:`R` of the evaluation point is a smooth stand-in for
    the voxel surface (Leeper et al.; CAT Sec. IV-B); the refined normal is
    :math:`-\nabla F / \|\nabla F\|`, pointing away from the occupied cells.

    The CAT paper used :math:`R = 1.5` cells at the contact point. Measured on
    tilted planes and yawed boxes (``tests/collision/test_normals.py``,
    ``docs/normal_refinement.md``) that setting is worse than the raw normal; the
    defaults here, :math:`R = 3` cells evaluated half a cell outside the obstacle
    witness point along the raw normal, are what measured best.
    """

    radius_cells: float = 3.0
    """Kernel radius R, in cells."""
    offset_cells: float = 0.5
    """Evaluation point: obstacle witness point + offset x cell along the raw normal."""

    def refine(
        self, index: CellIndex, points: FloatArray, normals: FloatArray
    ) -> FloatArray:
        """Refined unit normals (k, 3); a raw normal is kept where F has no gradient.

        Args:
            index: the occupied cells.
            points: obstacle witness points (k, 3).
            normals: their raw unit normals, out of the obstacle (k, 3).
        """
        out = np.array(normals, dtype=float, order="C").reshape(-1, 3)
        if len(out) == 0 or len(index) == 0:
            return out
        at = points + (self.offset_cells * index.cell) * out
        index.metaball_normals(at, self.radius_cells * index.cell, out)
        return out


class OccupancyEnvironment(Environment):
    """An occupancy map: occupied cell centres, indexed by brick (and a coal octree).

    Built once per map update (a few ms for tens of thousands of cells). A query
    measures the cells inside each robot shape's box, grown by the margin, in one
    compiled pass (:mod:`cbp.collision.cell_kernels`): a cell's largest excess over a
    hull's face planes is its signed distance to the hull where the nearest
    feature is a face (exact there, and a lower bound near edges and corners, so
    never an overestimate); capsules are measured exactly, against their axis.
    Cells are cubes: the distance to a cell is its centre's less half a cell
    (the cube's inscribed sphere: up to 0.37 of a cell more than the distance to
    its farthest-reaching corner, where a face is tilted to the grid). The
    collision world inflates map obstacles by another half cell
    (:attr:`resolution`), which covers that: the distance the constraints see
    is never more than the distance to any point of the cube. The
    closest cell per face (or direction) is a candidate; a few representative
    contacts per shape are kept, and their normals refined.

    The coal octree serves the yes-or-no checks of planners
    (:class:`~cbp.collision.checker.FreeSpaceChecker`). Coal's own octree contact
    query was slower (every voxel within the margin is visited) and off by up to
    4.5 mm and 14 deg on hulls (``benchmarks/RESULTS.md``, issue 3).

    A map built from a dense grid (:meth:`cbp.perception.OccupancyGrid.environment`)
    indexes only the shell of its obstacle cells, those next to open space, and
    keeps the grid's obstacle mask for :meth:`inside` (``surfaces_only``).

    Args:
        centres: occupied cell centres (N, 3) [m] (with ``index``: ignored).
        cell: cell size [m].
        refiner: normal refinement, or None to keep the hull faces' normals.
        index: the cells already indexed by brick (a map's compiled pass).
        blocked: the dense obstacle mask the cells are the shell of.
    """

    #: The compiled query's tables are built for the query's reach (margin plus
    #: half a cell) rounded up to whole steps of this [m]; 0: the reach itself.
    #: A snapshot queried at a margin that changes from one snapshot to the
    #: next (:mod:`cbp.perception.moving`) rounds it, so that a new table (a
    #: build per hull) is rare.
    reach_step: float = 0.0

    def __init__(
        self,
        centres: FloatArray,
        cell: float,
        refiner: MetaballRefiner | None = None,
        *,
        index: CellIndex | None = None,
        blocked: BlockedGrid | None = None,
    ) -> None:
        """Index the centres (the octree is built when a checker first asks)."""
        self.cell = float(cell)
        self.index = (
            index
            if index is not None
            else CellIndex(
                np.ascontiguousarray(centres, dtype=float).reshape(-1, 3), self.cell
            )
        )
        self.centres = (
            self.index.centres
            if index is not None
            else np.ascontiguousarray(centres, dtype=float).reshape(-1, 3)
        )
        self.resolution = 0.5 * self.cell
        self.refiner = refiner
        #: Per robot shape, how much nearer its contacts are reported [m]
        #: (obstacles that come at it, measured ahead: :meth:`ahead`).
        self.nearer: FloatArray | None = None
        #: The capture time of the newest frame in this snapshot [s of the
        #: run's clock] (None: not built from frames); its age is now - stamp.
        self.stamp: float | None = None
        self.blocked = blocked
        self.surfaces_only = blocked is not None
        self._identity = pin.SE3.Identity()
        self._last_query: tuple[tuple[object, ...], CellContactQuery | None] = (
            (),
            None,
        )

    def __len__(self) -> int:
        """Number of occupied cells."""
        return len(self.centres)

    def ahead(self, nearer: FloatArray | None) -> OccupancyEnvironment:
        """The same cells, each shape's contacts ``nearer`` (per shape) [m].

        A new snapshot object sharing this one's cells and index (its users
        tell snapshots apart by identity); None: as measured.
        """
        out = copy.copy(self)
        out.nearer = None if nearer is None else np.asarray(nearer, dtype=float)
        return out

    def prepare(self, shapes: list[LinkShape], margin: float) -> None:
        """Compile the query (once per process) and pack the shapes (once)."""
        compile_kernels()
        ShapeTable.for_shapes(shapes, self.table_reach(margin))

    def table_reach(self, margin: float) -> float:
        """The reach the query's table is built for at ``margin`` [m]."""
        reach = margin + 0.5 * self.cell
        step = self.reach_step
        return math.ceil(reach / step - 1e-9) * step if step > 0.0 else reach

    @functools.cached_property
    def tree(self) -> cKDTree:
        """A k-d tree of the cell centres (built on first use, for clearances)."""
        return cKDTree(self.centres)

    @functools.cached_property
    def octree(self) -> coal.OcTree | None:
        """The coal octree of the cells (built on first use; None for no cells).

        Only planners' yes-or-no checks use it, so a map update that no planner
        reads does not pay for it (2-12 ms for 10-50k cells).
        """
        if not len(self.centres):
            return None
        return coal.makeOctree(self.centres, self.cell)

    def collision_objects(self) -> list[tuple[str, coal.CollisionGeometry, pin.SE3]]:
        """The octree (none while the map is empty)."""
        if self.octree is None:
            return []
        return [("octree", self.octree, self._identity)]

    def inside(self, points: FloatArray) -> np.ndarray:
        """Which points (n, 3) lie in an obstacle cell (unknown ones included)."""
        if self.blocked is not None:
            return self.blocked.contains(points)
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if not len(self.centres):
            return np.zeros(len(points), dtype=bool)
        d, _ = self.tree.query(points, p=np.inf)
        return np.asarray(d <= 0.5 * self.cell)

    def query(
        self,
        robot: PlacedShapes,
        margin: float,
        per_shape: int,
        narrow_phase: NarrowPhase = "compiled",
    ) -> ContactSet:
        """Cell contacts per shape, reduced to ``per_shape``, normals refined.

        The shapes' own boxes bound the cells measured (not their spheres);
        the cells are always measured by the compiled pass (``narrow_phase``
        is for declared shapes).
        """
        del narrow_phase
        return self._cells(robot.shapes, robot.placements, margin, per_shape)

    def query_with_self(self, whole: WholeQuery) -> ContactSet | None:
        """:meth:`query` and the self pairs from the shapes' frames, no placements.

        The cells' compiled pass and the self pairs' (as the declared objects'
        query measures them) from ``whole.frames`` (n, 4, 4), without the pinocchio
        placements :meth:`query` takes (building them cost more than the
        cells' pass); see :meth:`Environment.query_with_self`. None for a
        snapshot whose query adds to this one's (moving cells), or when a self
        pair needs coal: the world then queries them apart.
        """
        if type(self).query is not OccupancyEnvironment.query:
            return None
        frames, table, moving = whole.frames, whole.table, whole.moving
        pairs = len(table.first)
        own = 0
        if pairs:
            centres_local, halves_local, radii, packed = table.bounds
            n = len(frames)
            centres, halves = np.empty((n, 3)), np.empty((n, 3))
            shape_bounds(frames, centres_local, halves_local, centres, halves)
            own_index, own_floats, left = contact_buffers(pairs)
            own, missed = self_contacts(
                (centres, halves, radii, frames, packed),
                table.pairs(float(whole.self_margin), float(whole.self_padding)),
                own_index,
                own_floats,
                left,
            )
            if missed:
                return None
        # The cells' contacts first, then the self contacts, in one buffer:
        # the set and its two parts are views of it (as ContactSet.stack).
        query = self._bound(whole.shapes, whole.margin, whole.per_shape, moving)
        index, floats, _ = contact_buffers((query.room if query else 0) + own)
        count = 0
        if query is not None:
            count = query.into(
                _Frames(frames if moving is None else frames[moving]),
                index[0],
                floats,
            )
            self._finish(index[0, :count], floats[:, :count], moving)
            index[1, :count] = -1
            floats[3, :count, 0] -= whole.padding
        if own:
            index[:, count : count + own] = own_index[:, :own]
            floats[:, count : count + own] = own_floats[:, :own]
        return ContactSet.packed(index, floats, count, count + own)

    def _bound(
        self,
        shapes: list[LinkShape],
        margin: float,
        per_shape: int,
        moving: IntArray | None,
    ) -> CellContactQuery | None:
        """The compiled query of ``shapes`` (those of ``moving``); None: no cells."""
        if not len(self.centres):
            return None
        refiner = self.refiner
        metaball = refiner if isinstance(refiner, MetaballRefiner) else None
        # The query bound to the last shapes and settings, kept as one tuple
        # (one atomic read, whatever thread queries).
        last, query = self._last_query
        if (
            query is None
            or shapes is not last[0]
            or margin != last[1]
            or per_shape != last[2]
            or refiner is not last[3]
            or moving is not last[4]
        ):
            # On the shape's surface, on the cell toward the shape, the normal
            # from the cell toward the shape; a few per shape, spread over
            # directions; a metaball refinement in the same compiled call,
            # another after it (:meth:`_finish`).
            measured = shapes if moving is None else [shapes[i] for i in moving]
            query = CellContactQuery(
                ShapeTable.for_shapes(measured, self.table_reach(margin)),
                self.index,
                margin,
                per_shape,
                _COS_SPREAD,
                (2.0 * self.cell) ** 2,
                None
                if metaball is None
                else (
                    metaball.radius_cells * self.cell,
                    metaball.offset_cells * self.cell,
                ),
            )
            self._last_query = ((shapes, margin, per_shape, refiner, moving), query)
        return query

    def _finish(
        self, shape: IntArray, floats: FloatArray, moving: IntArray | None
    ) -> None:
        """A query's contacts (:meth:`CellContactQuery.into`) as reported, in place.

        The shapes by their index among all (``moving``: the measured ones'),
        normals refined by a refiner other than the metaball, distances
        ``nearer``.
        """
        if moving is not None:
            shape[:] = moving[shape]
        refiner = self.refiner
        metaball = refiner if isinstance(refiner, MetaballRefiner) else None
        if refiner is not None and metaball is None:  # the metaball's is done
            floats[2] = refiner.refine(self.index, floats[1], floats[2])
        if self.nearer is not None:
            floats[3, :, 0] -= self.nearer[shape]

    def _cells(
        self,
        shapes: list[LinkShape],
        placements: ShapePlacements,
        margin: float,
        per_shape: int,
    ) -> ContactSet:
        """The cells' contacts of ``shapes`` at ``placements`` (:meth:`query`)."""
        query = self._bound(shapes, margin, per_shape, None)
        if query is None:
            return ContactSet.empty()
        index, floats, _ = contact_buffers(query.room)
        count = query.into(placements, index[0], floats)
        if not count:
            return ContactSet.empty()
        self._finish(index[0, :count], floats[:, :count], None)
        return ContactSet.obstacles(
            index[0, :count],
            floats[0, :count],
            floats[1, :count],
            floats[2, :count],
            floats[3, :count, 0],
        )

    def clearance(self, points: FloatArray) -> FloatArray:
        """Distance to the nearest occupied cell (centre distance - half a cell)."""
        if not len(self.centres):
            return np.full(len(points), np.inf)
        d, _ = self.tree.query(points)
        return np.asarray(d, dtype=float) - 0.5 * self.cell


class _Frames(ShapePlacements):
    """Shape placements as homogeneous matrices only (no pinocchio SE3s).

    For the compiled cell pass, which reads :attr:`homogeneous` only.
    """

    def __init__(self, frames: FloatArray) -> None:
        """Keep the matrices (n, 4, 4)."""
        list.__init__(self)
        self.homogeneous = frames


#: Occupancy contacts of one shape closer than this angle (25 degrees) and two
#: cells apart are one contact (:func:`cell_hits`).
_COS_SPREAD = math.cos(math.radians(25.0))
