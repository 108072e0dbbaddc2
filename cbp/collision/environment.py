# SPDX-License-Identifier: Apache-2.0
"""What the robot can collide with: declared objects, or an occupancy map.

Both sources answer one question through :meth:`Environment.query`: for each robot
shape, which obstacle points lie within a margin, with the signed distance and the
normal pointing from the obstacle toward the robot. Queries go through coal, with
the obstacle as the first object, so that the normal convention is the same for
shapes and octrees (coal reports the normal from the first object to the second
for shapes, and out of the occupied cell for octrees).
"""

from __future__ import annotations

import abc
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import trimesh
from scipy.spatial import cKDTree

from cbp.collision.broad import near_objects
from cbp.collision.cells import (
    CellIndex,
    ShapeTable,
    cell_hits,
    compile_kernels,
    spread_contacts,
)
from cbp.collision.geometry import LinkShape
from cbp.errors import ConfigError
from cbp.robot import FloatArray, IntArray

__all__ = [
    "BlockedGrid",
    "Environment",
    "EnvironmentObject",
    "Hits",
    "MetaballRefiner",
    "OccupancyEnvironment",
    "PrimitiveEnvironment",
    "signed_distance",
]


@dataclass
class Hits:
    """Raw contacts of robot shapes with obstacles (world frame).

    Attributes:
        shape: index of the robot shape, (K,).
        robot_point: witness point on the (unpadded) robot shape, (K, 3).
        obstacle_point: witness point on the obstacle, (K, 3).
        normal: unit normal from the obstacle toward the robot, (K, 3).
        distance: signed distance of the unpadded shapes [m], negative when they
            overlap (then its magnitude is the penetration depth), (K,).
    """

    shape: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    robot_point: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    obstacle_point: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    normal: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    distance: FloatArray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def from_rows(
        cls, rows: list[tuple[int, FloatArray, FloatArray, FloatArray, float]]
    ) -> Hits:
        """Stack (shape, robot point, obstacle point, normal, distance) tuples."""
        if not rows:
            return cls()
        shape, rp, op, n, d = zip(*rows, strict=True)
        return cls(
            np.array(shape, dtype=np.intp),
            np.array(rp, dtype=float),
            np.array(op, dtype=float),
            np.array(n, dtype=float),
            np.array(d, dtype=float),
        )

    def select(self, index: IntArray) -> Hits:
        """The contacts at ``index``."""
        return Hits(
            self.shape[index],
            self.robot_point[index],
            self.obstacle_point[index],
            self.normal[index],
            self.distance[index],
        )

    def __len__(self) -> int:
        """Number of contacts."""
        return int(self.shape.size)


def signed_distance(
    other: coal.CollisionGeometry,
    other_placement: pin.SE3,
    shape: coal.CollisionGeometry,
    placement: pin.SE3,
    request: coal.DistanceRequest,
    result: coal.DistanceResult,
) -> tuple[float, FloatArray, FloatArray, FloatArray]:
    """Signed distance from ``other`` to ``shape`` (coal's GJK/EPA), with witnesses.

    ``other`` goes first, so coal's normal points from it toward ``shape``.

    Returns:
        (distance, point on ``shape``, point on ``other``, unit normal from
        ``other`` toward ``shape``); the distance is negative when they overlap.
    """
    result.clear()
    d = coal.distance(other, other_placement, shape, placement, request, result)
    # The nearest points come back as new arrays; the normal is a view into
    # ``result``, which the next query overwrites.
    return (
        float(d),
        result.getNearestPoint2(),
        result.getNearestPoint1(),
        np.array(result.normal),
    )


class Environment(abc.ABC):
    """A static snapshot of the obstacles; replaced, never modified, when it changes."""

    #: How far the represented surfaces may be from the real ones [m]: 0 for
    #: declared objects, half a cell for an occupancy map. Step validation
    #: tolerates this much more penetration (the links' padding covers it).
    resolution: float = 0.0

    @abc.abstractmethod
    def query(
        self,
        shapes: list[LinkShape],
        placements: list[pin.SE3],
        centres: FloatArray,
        radii: FloatArray,
        margin: float,
        per_shape: int,
        halves: FloatArray | None = None,
    ) -> Hits:
        """Contacts of each robot shape with obstacles closer than ``margin``.

        Args:
            shapes: the robot's shapes.
            placements: their world placements; from a collision world, a
                :class:`~cbp.collision.geometry.ShapePlacements` that also holds
                them stacked as homogeneous matrices.
            centres: their bounding-sphere centres in the world, (n, 3).
            radii: their bounding-sphere radii, (n,).
            margin: report obstacles whose distance to a shape is below this [m].
            per_shape: at most this many contacts per shape (the closest, spread
                over distinct directions).
            halves: half extents of world-aligned boxes around the shapes about
                ``centres``, (n, 3), for a tighter broad phase (None: spheres).
        """

    def prepare(self, shapes: list[LinkShape], margin: float) -> None:
        """Get ready for queries of ``shapes`` up to ``margin``: build, compile.

        Called when a world takes this snapshot, in the thread that hands it over
        (the map thread), so that the control loop's first query pays nothing
        extra. Nothing to do by default.
        """
        del shapes, margin

    @abc.abstractmethod
    def collision_objects(self) -> list[tuple[str, coal.CollisionGeometry, pin.SE3]]:
        """The obstacles as coal geometries: (name, shape, world placement).

        For yes-or-no checks (:class:`~cbp.collision.checker.FreeSpaceChecker`).
        """

    #: True when :meth:`collision_objects` holds only the obstacles' surfaces
    #: (a map's shell of cells next to open space): a shape wholly inside an
    #: obstacle then touches none of them, and checks ask :meth:`inside` too.
    surfaces_only: bool = False

    @abc.abstractmethod
    def clearance(self, points: FloatArray) -> FloatArray:
        """Distance from each point (n, 3) to the nearest obstacle [m].

        For tests and plots; not used in the control loop.
        """

    def inside(self, points: FloatArray) -> np.ndarray:
        """Which points (n, 3) lie in an obstacle (boolean (n,))."""
        return np.asarray(self.clearance(points) <= 0.0)


# ---------------------------------------------------------------- declared objects


@dataclass(frozen=True)
class EnvironmentObject:
    """One declared obstacle: a coal shape at a world placement.

    Attributes:
        name: object name (from the scenario).
        shape: the coal shape (Box, Sphere, Cylinder, Convex or BVH mesh).
        placement: world placement of the shape's frame.
        lower: world AABB lower corner, (3,).
        upper: world AABB upper corner, (3,).
    """

    name: str
    shape: coal.CollisionGeometry
    placement: pin.SE3
    lower: FloatArray
    upper: FloatArray

    @classmethod
    def make(
        cls, name: str, shape: coal.CollisionGeometry, placement: pin.SE3
    ) -> EnvironmentObject:
        """Wrap a shape, computing its world bounding box."""
        shape.computeLocalAABB()
        lo = np.asarray(shape.aabb_local.min_, dtype=float)
        hi = np.asarray(shape.aabb_local.max_, dtype=float)
        corners = np.array(
            [
                [x, y, z]
                for x in (lo[0], hi[0])
                for y in (lo[1], hi[1])
                for z in (lo[2], hi[2])
            ]
        )
        world = corners.dot(placement.rotation.T) + placement.translation
        return cls(name, shape, placement, world.min(axis=0), world.max(axis=0))

    @classmethod
    def primitive(
        cls, name: str, kind: str, size: tuple[float, ...], placement: pin.SE3
    ) -> EnvironmentObject:
        """A box (edges x, y, z), sphere (radius) or cylinder (radius, length)."""
        if kind == "box":
            shape = coal.Box(*size)
        elif kind == "sphere":
            shape = coal.Sphere(size[0])
        elif kind == "cylinder":
            shape = coal.Cylinder(size[0], size[1])
        else:
            raise ConfigError(
                f"unknown primitive '{kind}'; expected box, sphere or cylinder"
            )
        return cls.make(name, shape, placement)

    @classmethod
    def mesh(
        cls, name: str, path: Path, scale: FloatArray, placement: pin.SE3
    ) -> EnvironmentObject:
        """A triangle mesh file (any format trimesh reads), kept non-convex."""
        try:
            mesh = trimesh.load(str(path), force="mesh")
        except (OSError, ValueError) as exc:
            raise ConfigError(f"cannot read mesh {path}: {exc}") from exc
        mesh.apply_scale(scale)
        model = coal.BVHModelOBBRSS()
        model.beginModel(len(mesh.faces), len(mesh.vertices))
        model.addSubModel(
            np.asarray(mesh.vertices, dtype=float),
            np.asarray(mesh.faces, dtype=np.int64),
        )
        model.endModel()
        return cls.make(name, model, placement)


TREE_MIN_OBJECTS = 32768
"""Above this many declared objects, a k-d tree picks those near the robot first.
Below it the compiled broad phase tests each object against the box around the
robot, which costs less (4,000 far objects add 4 us to a query; the tree query
alone takes 14 us)."""


class PrimitiveEnvironment(Environment):
    """Declared objects (ground truth), with a bounding-box broad phase.

    Only the (shape, object) pairs whose bounding sphere and box are within the
    margin reach coal, so the cost grows with the objects near the robot.
    """

    def __init__(self, objects: list[EnvironmentObject]) -> None:
        """Index the objects' bounding boxes."""
        self.objects = list(objects)
        self._lower = np.array([o.lower for o in objects]).reshape(-1, 3)
        self._upper = np.array([o.upper for o in objects]).reshape(-1, 3)
        # Objects far from the whole robot are skipped with one k-d tree query
        # on their box centres, so the cost grows with the objects nearby.
        self._box_centres = 0.5 * (self._lower + self._upper)
        self._box_reach = (
            float(np.linalg.norm(self._upper - self._lower, axis=1).max()) / 2
            if objects
            else 0.0
        )
        self._tree = cKDTree(self._box_centres)
        self._all = np.arange(len(objects), dtype=np.intp)
        self._request = coal.DistanceRequest()
        self._result = coal.DistanceResult()

    def prepare(self, shapes: list[LinkShape], margin: float) -> None:
        """Compile the contact reduction (once per process)."""
        del shapes, margin
        compile_kernels()

    def query(
        self,
        shapes: list[LinkShape],
        placements: list[pin.SE3],
        centres: FloatArray,
        radii: FloatArray,
        margin: float,
        per_shape: int,
        halves: FloatArray | None = None,
    ) -> Hits:
        """Exact distances of the candidate pairs; one contact per pair.

        Candidates: the objects whose bounding box is within ``margin`` of a
        shape's bounding sphere and (given ``halves``) of its box.
        """
        if not self.objects:
            return Hits()
        candidates = self._near_robot(centres, radii, margin)
        if not candidates.size:
            return Hits()
        if halves is None:
            halves = np.full_like(centres, np.inf)  # no box test: spheres only
        capacity = len(centres) * len(candidates)
        shape_index = np.empty(capacity, dtype=np.intp)
        object_index = np.empty(capacity, dtype=np.intp)
        count = near_objects(
            centres,
            halves,
            radii,
            self._lower,
            self._upper,
            candidates,
            margin,
            shape_index,
            object_index,
        )
        rows: list[tuple[int, FloatArray, FloatArray, FloatArray, float]] = []
        request, result = self._request, self._result
        for i, k in zip(
            shape_index[:count].tolist(), object_index[:count].tolist(), strict=True
        ):
            obj = self.objects[k]
            d, point, other, normal = signed_distance(
                obj.shape,
                obj.placement,
                shapes[i].shape,
                placements[i],
                request,
                result,
            )
            if d < margin:
                rows.append((i, point, other, normal, d))
        hits = Hits.from_rows(rows)
        if len(rows) <= per_shape:  # no shape can have too many (counted in Python)
            return hits
        return _keep_closest(hits, per_shape, min_angle_deg=0.0, min_spacing=0.0)

    def collision_objects(self) -> list[tuple[str, coal.CollisionGeometry, pin.SE3]]:
        """Every declared object."""
        return [(o.name, o.shape, o.placement) for o in self.objects]

    def _near_robot(
        self, centres: FloatArray, radii: FloatArray, margin: float
    ) -> IntArray:
        """Indices of the objects that may be within ``margin`` of the robot."""
        if len(self.objects) <= TREE_MIN_OBJECTS:
            return self._all
        # The boxes whose centres are near the robot's bounding sphere (around
        # the spheres of all its shapes).
        middle = 0.5 * (centres.min(axis=0) + centres.max(axis=0))
        offset = centres - middle
        reach = float((np.sqrt(np.einsum("ij,ij->i", offset, offset)) + radii).max())
        found = self._tree.query_ball_point(middle, reach + margin + self._box_reach)
        return np.array(found, dtype=np.intp)

    def clearance(self, points: FloatArray) -> FloatArray:
        """Exact distance from each point to the nearest object."""
        probe = coal.Sphere(1e-9)
        out = np.full(len(points), np.inf)
        for k, p in enumerate(points):
            for obj in self.objects:
                self._result.clear()
                d = coal.distance(
                    obj.shape,
                    obj.placement,
                    probe,
                    pin.SE3(np.eye(3), p),
                    self._request,
                    self._result,
                )
                out[k] = min(out[k], d)
        return out


# ---------------------------------------------------------------- occupancy map


@dataclass(frozen=True)
class BlockedGrid:
    """Which cells of a dense grid are obstacles: occupied, or unknown and counted so.

    Attributes:
        mask: True for obstacle cells, (nx, ny, nz).
        lower: the grid's lower corner [m].
        cell: cell size [m].
    """

    mask: np.ndarray
    lower: FloatArray
    cell: float

    def contains(self, points: FloatArray) -> np.ndarray:
        """Which points (n, 3) lie in an obstacle cell; outside the grid: none."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        idx = np.floor((points - self.lower) / self.cell).astype(np.intp)
        inside = np.all((idx >= 0) & (idx < np.array(self.mask.shape)), axis=1)
        out = np.zeros(len(points), dtype=bool)
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
    compiled pass (:mod:`cbp.collision.cells`): a cell's largest excess over a
    hull's face planes is its signed distance to the hull where the nearest
    feature is a face (exact there, and a lower bound near edges and corners, so
    never an overestimate); capsules are measured exactly, against their axis.
    Cells are cubes: the distance to a cell is its centre's less half a cell. The
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
        self.blocked = blocked
        self.surfaces_only = blocked is not None
        self._identity = pin.SE3.Identity()
        self._last_table: tuple[object, float, ShapeTable | None] = (None, 0.0, None)

    def __len__(self) -> int:
        """Number of occupied cells."""
        return len(self.centres)

    def prepare(self, shapes: list[LinkShape], margin: float) -> None:
        """Compile the query (once per process) and pack the shapes (once)."""
        compile_kernels()
        ShapeTable.for_shapes(shapes, margin + 0.5 * self.cell)

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
        shapes: list[LinkShape],
        placements: list[pin.SE3],
        centres: FloatArray,
        radii: FloatArray,
        margin: float,
        per_shape: int,
        halves: FloatArray | None = None,
    ) -> Hits:
        """Cell contacts per shape, reduced to ``per_shape``, normals refined.

        The shapes' own boxes bound the cells measured: ``centres``, ``radii``
        and ``halves`` are not used.
        """
        if not len(self.centres):
            return Hits()
        half = 0.5 * self.cell
        # The table of the last query's shapes, kept as one tuple (one atomic
        # read, whatever thread queries), else the shared cache's.
        last_shapes, last_margin, table = self._last_table
        if table is None or shapes is not last_shapes or margin != last_margin:
            table = ShapeTable.for_shapes(shapes, margin + half)
            self._last_table = (shapes, margin, table)
        shape, centre, outward, distance = table.candidates(
            self.index, placements, margin
        )
        if not len(shape):
            return Hits()
        # On the shape's surface, on the cell toward the shape, the normal from
        # the cell toward the shape; a few per shape, spread over directions.
        hits = Hits(
            *cell_hits(
                shape,
                centre,
                outward,
                distance,
                half,
                per_shape,
                _COS_SPREAD,
                (2.0 * self.cell) ** 2,
            )
        )
        if self.refiner is not None and len(hits):
            hits.normal = self.refiner.refine(
                self.index, hits.obstacle_point, hits.normal
            )
        return hits

    def clearance(self, points: FloatArray) -> FloatArray:
        """Distance to the nearest occupied cell (centre distance - half a cell)."""
        if not len(self.centres):
            return np.full(len(points), np.inf)
        d, _ = self.tree.query(points)
        return np.asarray(d, dtype=float) - 0.5 * self.cell


#: Occupancy contacts of one shape closer than this angle (25 degrees) and two
#: cells apart are one contact (:func:`cell_hits`).
_COS_SPREAD = math.cos(math.radians(25.0))


def _keep_closest(
    hits: Hits, per_shape: int, min_angle_deg: float, min_spacing: float
) -> Hits:
    """Keep up to ``per_shape`` contacts per shape, spread over directions.

    The closest first, then the next closest that differ from every kept one in
    normal (by ``min_angle_deg``) or position (by ``min_spacing``): a few contacts
    that span the directions the shape is blocked in, instead of one per voxel.
    """
    if len(hits) == 0:
        return hits
    if min_spacing <= 0.0 and np.bincount(hits.shape).max() <= per_shape:
        return hits  # nothing to drop (the common case against declared objects)
    order = np.lexsort((hits.distance, hits.shape))
    keep = np.empty(len(hits), dtype=np.intp)
    count = spread_contacts(
        order,
        hits.shape,
        hits.normal,
        hits.robot_point,
        per_shape,
        math.cos(math.radians(min_angle_deg)),
        min_spacing * min_spacing,
        keep,
    )
    return hits.select(keep[:count])
