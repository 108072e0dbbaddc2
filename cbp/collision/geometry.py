# SPDX-License-Identifier: Apache-2.0
"""The robot's collision geometry: one convex shape per URDF collision element.

Each ``<collision>`` element of the URDF becomes a :class:`LinkShape`: a coal shape
(URDF primitives as they are, meshes replaced by their convex hull, built with
trimesh since the coal wheel has no qhull), its placement on a frame of the model,
a bounding sphere for the broad phase, and the hull's half-spaces for filtering the
robot out of depth images. Padding is not baked into the shapes: every query
subtracts it from the distances, which is exactly the distance to the shape grown
by a sphere of that radius.
"""

from __future__ import annotations

import functools
import itertools
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import coal
import numba
import numpy as np
import numpy.typing as npt
import pinocchio as pin
import trimesh
from scipy.optimize import minimize

from cbp.collision.broad import near_pairs
from cbp.errors import ConfigError, FrameNotFoundError, suggestion
from cbp.files import load_mesh
from cbp.robot import Approximation, FloatArray, IntArray, RobotModel
from cbp.state import RobotState

__all__ = [
    "UNREAD_VISUAL_EXCESS",
    "Attachment",
    "LinkShape",
    "RobotGeometry",
    "ShapePlacements",
    "WorldShapes",
    "find_ignorable_pairs",
    "fit_capsule",
    "inside_any",
    "inside_convex",
    "points_inside",
]


log = logging.getLogger(__name__)

#: How far a link is taken to look larger than its collision shapes when its
#: visual meshes cannot be read [m] (the self-filter's reach before it was
#: measured from the shapes).
UNREAD_VISUAL_EXCESS = 0.03


class ShapePlacements(list[pin.SE3]):
    """The robot shapes' world placements, in shape order, also stacked.

    A list of pinocchio SE3 (what coal's distance calls take) that keeps their
    homogeneous matrices in one array, ``homogeneous`` (n, 4, 4), made once per
    query for the compiled loops that read them all.
    """

    def __init__(self, placements: list[pin.SE3]) -> None:
        """Keep the placements and stack their matrices."""
        super().__init__(placements)
        self.homogeneous: FloatArray = np.array(
            [M.homogeneous for M in placements]
        ).reshape(-1, 4, 4)


@dataclass(frozen=True)
class PlacedShapes:
    """A robot's shapes at one configuration, as environments query them.

    Attributes:
        shapes: the shapes (:attr:`RobotGeometry.shapes`).
        placements: their world placements, also stacked.
        centres: their bounding-sphere centres in the world (n, 3) [m].
        radii: their bounding-sphere radii (n,) [m].
        halves: half extents of world-aligned boxes around the shapes about
            ``centres`` (n, 3) [m], for a tighter broad phase.
    """

    shapes: list[LinkShape]
    placements: ShapePlacements
    centres: FloatArray
    radii: FloatArray
    halves: FloatArray


@dataclass(frozen=True)
class LinkShape:
    """One convex collision shape fixed on a frame of the robot.

    Attributes:
        name: the geometry's name (``<link>_<index>``).
        link: the link (frame) name that carries it.
        frame_id: index of that frame in the model.
        joint_id: the joint that moves the frame.
        placement: the shape's pose in the frame.
        shape: the coal shape.
        centre: bounding-sphere centre in the frame [m], shape (3,).
        radius: bounding-sphere radius [m].
        planes: hull half-spaces in the frame, (F, 4): ``n . x <= d`` as (n, d).
        lower: the hull's bounding-box corner, axes of the frame [m], shape (3,).
        upper: the opposite corner [m], shape (3,).
    """

    name: str
    link: str
    frame_id: int
    joint_id: int
    placement: pin.SE3
    shape: coal.ShapeBase
    centre: FloatArray
    radius: float
    planes: FloatArray
    lower: FloatArray
    upper: FloatArray

    @classmethod
    def probe(cls, name: str, shape: coal.ShapeBase) -> LinkShape:
        """A primitive on the world frame (frame 0), for studies and tests."""
        mesh = _primitive_mesh(shape)
        vertices = np.asarray(mesh.vertices)
        lower, upper = vertices.min(axis=0), vertices.max(axis=0)
        centre = 0.5 * (lower + upper)
        return cls(
            name=name,
            link=name,
            frame_id=0,
            joint_id=0,
            placement=pin.SE3.Identity(),
            shape=shape,
            centre=centre,
            radius=float(np.linalg.norm(vertices - centre, axis=1).max()),
            planes=_planes(mesh),
            lower=lower,
            upper=upper,
        )

    @functools.cached_property
    def plane_normals_t(self) -> npt.NDArray[np.float32]:
        """The face planes' normals as contiguous float32 columns, (3, F).

        For matrix products with many points: a strided slice of ``planes`` makes
        numpy skip BLAS (10x slower), and float32 is exact to 0.1 um here.
        """
        return np.ascontiguousarray(self.planes[:, :3].T, dtype=np.float32)

    @functools.cached_property
    def plane_offsets(self) -> npt.NDArray[np.float32]:
        """The face planes' offsets d (n . x <= d), float32, (F,)."""
        return np.ascontiguousarray(self.planes[:, 3], dtype=np.float32)

    def world_placement(self, state: RobotState) -> pin.SE3:
        """The shape's placement in the world at ``state``."""
        return state.data.oMf[self.frame_id] * self.placement


@dataclass(frozen=True)
class Attachment:
    """A rigid body fixed on a robot frame that the URDF does not hold.

    A mounted camera's housing, a tool: checked like the URDF's collision shapes
    (padding, contacts, self-collision with non-adjacent bodies, the depth
    images' self-filter).

    Attributes:
        name: the shape's name.
        frame: the robot frame that carries it.
        placement: its pose in that frame.
        shape: a coal primitive (box, sphere, cylinder or capsule).
    """

    name: str
    frame: str
    placement: pin.SE3
    shape: coal.ShapeBase


def _hull_shape(path: Path, scale: FloatArray) -> tuple[coal.Convex, trimesh.Trimesh]:
    mesh = load_mesh(path, "collision mesh")
    mesh.apply_scale(scale)
    hull = mesh.convex_hull
    points = coal.StdVec_Vec3s()
    for v in np.asarray(hull.vertices, dtype=float):
        points.append(v)
    triangles = coal.StdVec_Triangle()
    for a, b, c in np.asarray(hull.faces):
        triangles.append(coal.Triangle(int(a), int(b), int(c)))
    return coal.Convex(points, triangles), hull


def _beyond_planes(points: FloatArray, planes: list[FloatArray]) -> float:
    """How far the farthest of ``points`` lies outside the nearest of some hulls.

    Per point, the distance beyond a hull's faces is its largest plane excess
    (n . x - d); the point is counted against the hull it is least beyond. 0
    when every point is inside a hull.
    """
    worst = 0.0
    for start in range(0, len(points), 4096):
        chunk = points[start : start + 4096]
        least = np.full(len(chunk), np.inf)
        for p in planes:
            least = np.minimum(least, (chunk.dot(p[:, :3].T) - p[:, 3]).max(axis=1))
        worst = max(worst, float(least.max()))
    return worst


def _segment_distances(points: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    ab = b - a
    t = np.clip((points - a).dot(ab) / max(float(ab.dot(ab)), 1e-12), 0.0, 1.0)
    return np.asarray(np.linalg.norm(points - (a + t[:, None] * ab), axis=1))


def fit_capsule(points: FloatArray) -> tuple[pin.SE3, float, float]:
    """The capsule of least volume (found locally) that contains ``points`` (n, 3).

    The axis starts on the points' principal axis; its ends and an offset of the
    axis are optimised (Nelder-Mead), with the radius set to the farthest point.

    Returns:
        (placement of the capsule's centre with its axis along local z, radius,
        full length of the axis segment).
    """
    centre = points.mean(axis=0)
    axis = np.linalg.svd(points - centre)[2][0]
    along = (points - centre).dot(axis)

    def ends(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        return centre + x[2:] + axis * x[0], centre + x[2:] + axis * x[1]

    def volume(x: FloatArray) -> float:
        a, b = ends(x)
        r = float(_segment_distances(points, a, b).max())
        return float(np.pi * r * r * np.linalg.norm(b - a) + 4.0 / 3.0 * np.pi * r**3)

    x0 = np.array([0.7 * along.min(), 0.7 * along.max(), 0.0, 0.0, 0.0])
    x = minimize(volume, x0, method="Nelder-Mead", options={"maxiter": 3000}).x
    a, b = ends(x)
    radius = float(_segment_distances(points, a, b).max())
    length = float(np.linalg.norm(b - a))
    z = (b - a) / length if length > 1e-9 else np.array([0.0, 0.0, 1.0])
    rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), z).matrix()
    return pin.SE3(rotation, 0.5 * (a + b)), radius, length


def _primitive_mesh(shape: coal.ShapeBase) -> trimesh.Trimesh:
    if isinstance(shape, coal.Box):
        return trimesh.creation.box(extents=2.0 * np.asarray(shape.halfSide))
    if isinstance(shape, coal.Sphere):
        return trimesh.creation.icosphere(subdivisions=2, radius=shape.radius)
    if isinstance(shape, coal.Cylinder):
        return trimesh.creation.cylinder(
            radius=shape.radius, height=2.0 * shape.halfLength
        )
    if isinstance(shape, coal.Capsule):
        return trimesh.creation.capsule(
            radius=shape.radius, height=2.0 * shape.halfLength
        )
    raise ConfigError(f"unsupported collision primitive {type(shape).__name__}")


def _planes(hull: trimesh.Trimesh) -> FloatArray:
    normals = np.asarray(hull.face_normals, dtype=float)
    offsets = np.einsum("ij,ij->i", normals, hull.triangles[:, 0, :])
    planes = np.hstack([normals, offsets[:, None]])
    # Coplanar triangles repeat a plane: keep one of each.
    planes = np.unique(np.round(planes, 9), axis=0)
    return planes[_spread_order(planes[:, :3])]


def _spread_order(normals: FloatArray) -> IntArray:
    """An order of the faces in which each next normal is the least like those before.

    Point-inside tests stop at the first plane a point lies beyond; with the
    normals spread this way, a point outside the hull is usually rejected within
    the first few planes (in sorted order, neighbouring planes face alike).
    """
    order = [0]
    likeness = normals.dot(normals[0])
    for _ in range(len(normals) - 1):
        likeness[order[-1]] = np.inf
        k = int(np.argmin(likeness))
        order.append(k)
        likeness = np.maximum(likeness, normals.dot(normals[k]))
    return np.asarray(order, dtype=np.int64)


class RobotGeometry:
    """The collision shapes of a robot, and the pairs checked for self-collision.

    Args:
        robot: a model loaded from a robot folder (its URDF gives the geometry).
        padding: distance added around every shape [m] (default: robot.yaml's).
        approximation: ``hull`` (convex hull of each mesh) or ``capsule`` (the
            least-volume capsule around the hull; faster against octrees, coarser);
            default: robot.yaml's.
        attachments: bodies fixed on the robot's frames beyond the URDF's
            (camera housings), after its shapes.

    Attributes:
        shapes: every checked shape, in URDF order.
        self_pairs: index pairs into ``shapes`` checked against each other: all
            pairs except shapes on one rigid body, on adjacent bodies, and the
            ``ignore_pairs`` of robot.yaml.
        padding: distance added around every shape [m].
        radii: the shapes' bounding-sphere radii [m], (n,).
    """

    def __init__(
        self,
        robot: RobotModel,
        padding: float | None = None,
        approximation: Approximation | None = None,
        attachments: Sequence[Attachment] = (),
    ) -> None:
        """Load the URDF's collision elements as convex shapes."""
        if robot.urdf_path is None:
            raise ConfigError(f"robot '{robot.name}' has no URDF to read geometry from")
        description = robot.description
        settings = description.collision if description is not None else None
        self.robot = robot
        self.padding = (
            padding if padding is not None else (settings.padding if settings else 0.0)
        )
        self.approximation: Approximation = approximation or (
            settings.approximation if settings else "hull"
        )
        model = robot.model
        # package://name/... resolves under any of these: the robot's folder,
        # the URDF's folder and the folders above it (a ROS package tree).
        urdf_folder = robot.urdf_path.resolve().parent
        folders = [robot.folder, urdf_folder, *list(urdf_folder.parents)[:3]]
        self._package_dirs = [str(f) for f in folders if f is not None]
        try:
            geometry_model = pin.buildGeomFromUrdf(
                model,
                str(robot.urdf_path),
                pin.GeometryType.COLLISION,
                package_dirs=self._package_dirs,
            )
        except (RuntimeError, ValueError) as exc:
            raise ConfigError(
                f"cannot read the collision geometry of {robot.urdf_path}: {exc}"
            ) from None
        self._attached = len(attachments)
        ignored_links = set(settings.ignore_links) if settings else set()
        links = {f.name for f in model.frames}
        for link in ignored_links - links:
            raise ConfigError(
                f"ignore_links: no link '{link}'{suggestion(link, links)}",
                "collision.ignore_links",
            )
        self.shapes: list[LinkShape] = []
        halves: list[FloatArray] = []
        for obj in geometry_model.geometryObjects:
            frame = model.frames[obj.parentFrame]
            if frame.name in ignored_links:
                continue
            placement = frame.placement.inverse() * obj.placement
            if obj.meshPath and isinstance(obj.geometry, coal.BVHModelBase):
                shape, hull = _hull_shape(Path(obj.meshPath), np.asarray(obj.meshScale))
                if self.approximation == "capsule":
                    offset, radius, length = fit_capsule(np.asarray(hull.vertices))
                    shape = coal.Capsule(radius, length)
                    hull = _primitive_mesh(shape)
                    placement = placement * offset
            else:
                shape = obj.geometry
                hull = _primitive_mesh(shape)
            self._add(obj.name, int(obj.parentFrame), placement, shape, hull, halves)
        for attached in attachments:
            try:
                frame_id = robot.frame_id(attached.frame)
            except FrameNotFoundError as exc:
                raise ConfigError(f"'{attached.name}': {exc}") from None
            self._add(
                attached.name,
                frame_id,
                attached.placement,
                attached.shape,
                _primitive_mesh(attached.shape),
                halves,
            )
        self.radii = np.array([s.radius for s in self.shapes])
        self.box_halves = np.array(halves).reshape(-1, 3)
        """Half extents of each shape's bounding box in its own frame, about its
        bounding-sphere centre [m], (n, 3): rotated into the world, a tighter
        broad phase than the sphere on long links and thin objects."""
        self.self_pairs = self._self_pairs(settings.ignore_pairs if settings else [])
        pairs = np.array(self.self_pairs, dtype=np.intp).reshape(-1, 2)
        # Contiguous copies: the compiled broad phase is compiled for them.
        self._pair_a = np.ascontiguousarray(pairs[:, 0])
        self._pair_b = np.ascontiguousarray(pairs[:, 1])

    def _add(
        self,
        name: str,
        frame_id: int,
        placement: pin.SE3,
        shape: coal.ShapeBase,
        hull: trimesh.Trimesh,
        halves: list[FloatArray],
    ) -> None:
        """Append the shape ``hull`` describes, placed on a frame."""
        frame = self.robot.model.frames[frame_id]
        vertices = np.asarray(hull.vertices)
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        centre_local = 0.5 * (lo + hi)
        halves.append(0.5 * (hi - lo))
        in_frame = vertices.dot(placement.rotation.T) + placement.translation
        self.shapes.append(
            LinkShape(
                name=name,
                link=frame.name,
                frame_id=frame_id,
                joint_id=int(frame.parentJoint),
                placement=placement,
                shape=shape,
                centre=placement.act(centre_local),
                radius=float(np.linalg.norm(vertices - centre_local, axis=1).max()),
                planes=_transform_planes(_planes(hull), placement),
                lower=in_frame.min(axis=0),
                upper=in_frame.max(axis=0),
            )
        )

    @functools.cached_property
    def visual_excess(self) -> FloatArray:
        """How far each shape's link looks larger than its shapes [m], (n,).

        A camera sees a link's visual geometry (the URDF's ``<visual>``
        elements), and that may reach past its collision shapes: this is the
        largest distance of a visual vertex beyond the face planes of the link's
        shapes (of the nearest one, where a link has several), 0 where the visual
        geometry lies inside. The depth images' self-filter grows each shape by
        it, so the robot's own readings are recognised however coarse its
        collision geometry is. Measured once, when first asked for. When the
        visual geometry cannot be read, every link gets
        :data:`UNREAD_VISUAL_EXCESS` (logged); attachments get 0 (nothing draws
        them but what they stand for).
        """
        robot = self.robot
        own = self.shapes[: len(self.shapes) - self._attached]
        excess = np.zeros(len(self.shapes))
        try:
            visual = pin.buildGeomFromUrdf(
                robot.model,
                str(robot.urdf_path),
                pin.GeometryType.VISUAL,
                package_dirs=self._package_dirs,
            )
        except (RuntimeError, ValueError) as exc:
            reason = next(
                (line for line in str(exc).splitlines() if "load resource" in line),
                str(exc).splitlines()[0] if str(exc) else type(exc).__name__,
            )
            log.warning(
                "cannot read the visual geometry of %s (%s): the depth images' "
                "self-filter takes every link to look %.0f mm larger than its "
                "collision shapes",
                robot.urdf_path,
                reason.strip(),
                1000 * UNREAD_VISUAL_EXCESS,
            )
            excess[: len(own)] = UNREAD_VISUAL_EXCESS
            return excess
        model = robot.model
        unfiltered = set()
        for obj in visual.geometryObjects:
            link = model.frames[obj.parentFrame].name
            on_link = [s for s, shape in enumerate(own) if shape.link == link]
            if not on_link:
                unfiltered.add(link)
                continue
            if isinstance(obj.geometry, coal.BVHModelBase):  # a mesh, scaled
                vertices = np.asarray(obj.geometry.vertices(), dtype=float)
            else:
                vertices = np.asarray(_primitive_mesh(obj.geometry).vertices)
            frame = model.frames[obj.parentFrame]
            placement = frame.placement.inverse() * obj.placement
            in_frame = vertices.dot(placement.rotation.T) + placement.translation
            beyond = _beyond_planes(in_frame, [own[s].planes for s in on_link])
            excess[on_link] = np.maximum(excess[on_link], beyond)
        if unfiltered:
            log.warning(
                "links with visual geometry but no collision shape: %s; depth "
                "readings of them are not taken for the robot",
                ", ".join(sorted(unfiltered)),
            )
        return excess

    def _self_pairs(self, ignore: list[tuple[str, str]]) -> list[tuple[int, int]]:
        model = self.robot.model
        link_names = {s.link for s in self.shapes}
        ignored = set()
        for a, b in ignore:
            for link in (a, b):
                if link not in link_names:
                    raise ConfigError(
                        f"ignore_pairs: no collision link '{link}'"
                        f"{suggestion(link, link_names)}",
                        "collision.ignore_pairs",
                    )
            ignored.add(frozenset((a, b)))
        pairs = []
        indexed = list(enumerate(self.shapes))
        for (i, first), (j, second) in itertools.combinations(indexed, 2):
            ja, jb = first.joint_id, second.joint_id
            adjacent = ja == jb or model.parents[ja] == jb or model.parents[jb] == ja
            if not adjacent and frozenset((first.link, second.link)) not in ignored:
                pairs.append((i, j))
        return pairs

    def non_adjacent_pairs(self) -> list[tuple[int, int]]:
        """Every pair of shapes on distinct, non-adjacent bodies (no ignore list)."""
        return self._self_pairs([])

    def geometry_model(self, padding: float = 0.0) -> pin.GeometryModel:
        """The shapes as a pinocchio geometry model (one object per shape, in order).

        Args:
            padding: grow every shape by this much [m] (coal's swept-sphere
                radius, on copies: the shapes here are left as they are).
        """
        model = pin.GeometryModel()
        frames = self.robot.model.frames
        for shape in self.shapes:
            geometry = shape.shape
            if padding > 0:
                geometry = geometry.clone()
                geometry.setSweptSphereRadius(geometry.getSweptSphereRadius() + padding)
            model.addGeometryObject(
                pin.GeometryObject(
                    shape.name,
                    shape.joint_id,
                    shape.frame_id,
                    frames[shape.frame_id].placement * shape.placement,
                    geometry,
                )
            )
        return model

    @property
    def pair_arrays(self) -> tuple[IntArray, IntArray]:
        """:attr:`self_pairs` as two contiguous arrays (first, second)."""
        return self._pair_a, self._pair_b

    def near_self_pairs(
        self, centres: FloatArray, margin: float, halves: FloatArray | None = None
    ) -> list[int]:
        """Indices into :attr:`self_pairs` whose bounding volumes nearly touch.

        The broad phase of self-collision: bounding spheres closer than
        ``margin`` and, given the half extents of world-aligned boxes around the
        shapes about the same centres (n, 3), boxes closer than ``margin`` too.
        """
        if halves is None:
            halves = np.full_like(centres, np.inf)  # no box test: spheres only
        out = np.empty(len(self._pair_a), dtype=np.intp)
        n = near_pairs(
            centres, halves, self.radii, self._pair_a, self._pair_b, margin, out
        )
        return out[:n].tolist()  # type: ignore[no-any-return]

    def world_spheres(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """Bounding-sphere centres (n, 3) in the world and radii (n,), unpadded."""
        oMf = state.data.oMf
        centres = np.array([oMf[s.frame_id].act(s.centre) for s in self.shapes])
        return centres.reshape(-1, 3), self.radii

    def world_shapes(self, state: RobotState) -> WorldShapes:
        """Every shape's half-spaces and bounding sphere in the world at ``state``.

        One compiled pass over the stacked planes (the map thread calls this per
        depth frame: one release of the GIL, not one per shape).
        """
        oMf = state.data.oMf
        frames = np.array([oMf[i].homogeneous for i in self._frame_ids]).reshape(
            -1, 4, 4
        )
        planes = np.empty_like(self._local_planes)
        centres = np.empty((len(self.shapes), 3))
        _place_shapes(
            self._local_planes,
            self._plane_start,
            self._local_centres,
            frames,
            planes,
            centres,
        )
        return WorldShapes(planes, self._plane_start, centres, self.radii, frames)

    @functools.cached_property
    def _frame_ids(self) -> list[int]:
        return [s.frame_id for s in self.shapes]

    @functools.cached_property
    def _local_planes(self) -> FloatArray:
        planes = [s.planes for s in self.shapes]
        return np.ascontiguousarray(np.vstack(planes)).reshape(-1, 4)

    @functools.cached_property
    def _local_centres(self) -> FloatArray:
        return np.array([s.centre for s in self.shapes], dtype=float).reshape(-1, 3)

    @functools.cached_property
    def _plane_start(self) -> IntArray:
        counts = [len(s.planes) for s in self.shapes]
        return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)

    def contains(
        self, state: RobotState, points: FloatArray, margin: float = 0.0
    ) -> np.ndarray:
        """Which points (n, 3) lie inside some shape grown by ``padding + margin``.

        Points within that distance of a hull's faces count as inside: the test is
        exact on faces and conservative (a little too large) near edges and corners.
        Returns a boolean array of shape (n,).
        """
        points = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)
        inside = np.empty(len(points), dtype=np.bool_)
        shapes = self.world_shapes(state)
        points_inside(
            points,
            shapes.planes,
            shapes.plane_start,
            shapes.centres,
            shapes.radii,
            np.full(len(self.shapes), self.padding + margin),
            inside,
        )
        return inside

    def __len__(self) -> int:
        """Number of shapes."""
        return len(self.shapes)

    def __repr__(self) -> str:
        """Robot, shapes and pair count."""
        return (
            f"RobotGeometry({self.robot.name!r}, shapes={len(self.shapes)}, "
            f"self_pairs={len(self.self_pairs)}, padding={self.padding})"
        )


@dataclass(frozen=True)
class WorldShapes:
    """A robot's convex shapes placed in the world, packed for compiled loops.

    Attributes:
        planes: half-spaces ``n . x <= d`` of every shape as rows (n, d), stacked,
            (P, 4).
        plane_start: shape s's planes are rows ``plane_start[s]`` to
            ``plane_start[s + 1]``, (shapes + 1,).
        centres: bounding-sphere centres (shapes, 3) [m].
        radii: bounding-sphere radii (shapes,) [m].
        frames: the frames that carry the shapes, as homogeneous matrices
            (shapes, 4, 4).
    """

    planes: FloatArray
    plane_start: IntArray
    centres: FloatArray
    radii: FloatArray
    frames: FloatArray


@numba.njit(cache=True, nogil=True)
def _place_shapes(
    local_planes: FloatArray,
    plane_start: IntArray,
    local_centres: FloatArray,
    frames: FloatArray,
    planes: FloatArray,
    centres: FloatArray,
) -> None:
    """Write each shape's planes and sphere centre placed by its frame (S, 4, 4)."""
    for s in range(frames.shape[0]):
        R = frames[s, :3, :3]
        t = frames[s, :3, 3]
        for p in range(plane_start[s], plane_start[s + 1]):
            d = local_planes[p, 3]
            for a in range(3):
                n = (
                    R[a, 0] * local_planes[p, 0]
                    + R[a, 1] * local_planes[p, 1]
                    + R[a, 2] * local_planes[p, 2]
                )
                planes[p, a] = n
                d += n * t[a]
            planes[p, 3] = d
        for a in range(3):
            centres[s, a] = (
                R[a, 0] * local_centres[s, 0]
                + R[a, 1] * local_centres[s, 1]
                + R[a, 2] * local_centres[s, 2]
                + t[a]
            )


@numba.njit(cache=True, nogil=True, inline="always")
def inside_convex(
    x: float,
    y: float,
    z: float,
    planes: FloatArray,
    start: int,
    stop: int,
    grow: float,
) -> bool:
    """Whether (x, y, z) is within ``grow`` of every plane of rows [start, stop)."""
    for p in range(start, stop):
        if planes[p, 0] * x + planes[p, 1] * y + planes[p, 2] * z - planes[p, 3] > grow:
            return False
    return True


@numba.njit(cache=True, nogil=True, inline="always")
def inside_any(
    x: float,
    y: float,
    z: float,
    planes: FloatArray,
    plane_start: IntArray,
    centres: FloatArray,
    radii: FloatArray,
    grow: FloatArray,
    extra: float = 0.0,
) -> bool:
    """Whether (x, y, z) is inside some shape s grown by ``grow[s] + extra``.

    The shapes as :class:`WorldShapes` gives them: each bounding sphere first,
    then the planes of the shapes whose grown sphere holds the point.
    """
    for s in range(radii.size):
        grown = grow[s] + extra
        dx, dy, dz = x - centres[s, 0], y - centres[s, 1], z - centres[s, 2]
        reach = radii[s] + grown
        if dx * dx + dy * dy + dz * dz > reach * reach:
            continue
        if inside_convex(x, y, z, planes, plane_start[s], plane_start[s + 1], grown):
            return True
    return False


@numba.njit(cache=True, nogil=True)
def points_inside(
    points: FloatArray,
    planes: FloatArray,
    plane_start: IntArray,
    centres: FloatArray,
    radii: FloatArray,
    grow: FloatArray,
    out: np.ndarray,
) -> int:
    """Flag the points (n, 3) inside some shape s grown by ``grow[s]``; count them.

    The shapes as :class:`WorldShapes` gives them; a point within ``grow[s]`` of
    every face plane of shape s counts as inside (exact on faces, a little
    generous at edges and corners).
    """
    count = 0
    for n in range(points.shape[0]):
        out[n] = inside_any(
            points[n, 0],
            points[n, 1],
            points[n, 2],
            planes,
            plane_start,
            centres,
            radii,
            grow,
        )
        if out[n]:
            count += 1
    return count


def _transform_planes(planes: FloatArray, placement: pin.SE3) -> FloatArray:
    """Half-spaces n.x <= d of a shape, moved from its own frame by ``placement``."""
    normals = planes[:, :3].dot(placement.rotation.T)
    offsets = planes[:, 3] + normals.dot(placement.translation)
    return np.hstack([normals, offsets[:, None]])


def find_ignorable_pairs(
    geometry: RobotGeometry,
    rng: np.random.Generator,
    samples: int = 2000,
) -> list[tuple[str, str]]:
    """Link pairs that never collide (or always do) over random configurations.

    The method of MoveIt's setup assistant: pairs that are in collision in no
    sampled configuration cannot usefully constrain motion and are skipped, and
    pairs in collision in every sample are a modelling artefact. Every
    non-adjacent pair is sampled, including those robot.yaml already ignores, so
    the result is the whole list: paste it under ``collision.ignore_pairs`` in
    robot.yaml. More samples, fewer misses.

    Raises:
        ValueError: ``samples`` is below 1.
    """
    if samples < 1:
        raise ValueError(f"samples must be >= 1, got {samples}")
    robot = geometry.robot
    state = RobotState(robot)
    counts = dict.fromkeys(geometry.non_adjacent_pairs(), 0)
    request = coal.CollisionRequest()
    result = coal.CollisionResult()
    for _ in range(samples):
        state.update(robot.random_configuration(rng))
        placements = [s.world_placement(state) for s in geometry.shapes]
        for i, j in counts:
            result.clear()
            if coal.collide(
                geometry.shapes[i].shape,
                placements[i],
                geometry.shapes[j].shape,
                placements[j],
                request,
                result,
            ):
                counts[(i, j)] += 1
    pairs = {
        tuple(sorted((geometry.shapes[i].link, geometry.shapes[j].link)))
        for (i, j), n in counts.items()
        if n in (0, samples)
    }
    return sorted((a, b) for a, b in pairs)
