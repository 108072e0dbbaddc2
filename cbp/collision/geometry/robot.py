# SPDX-License-Identifier: Apache-2.0
"""A robot's collision shapes from its URDF, and the pairs checked against each other.

Each ``<collision>`` element becomes a :class:`~cbp.collision.geometry.LinkShape`
(meshes replaced by their convex hull, :mod:`cbp.collision.geometry.hulls`);
attachments add shapes the URDF does not hold. Self-collision pairs leave out
shapes on one body, on adjacent bodies, and robot.yaml's ``ignore_pairs``
(:func:`find_ignorable_pairs` finds candidates).
"""

from __future__ import annotations

import functools
import itertools
import logging
from collections.abc import Sequence
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import trimesh

from cbp.collision.broad import near_pairs
from cbp.collision.geometry.hulls import (
    beyond_planes,
    face_planes,
    fit_capsule,
    hull_shape,
    primitive_mesh,
    transform_planes,
)
from cbp.collision.geometry.inside import place_shapes, points_inside
from cbp.collision.geometry.shapes import Attachment, LinkShape, WorldShapes
from cbp.errors import ConfigError, FrameNotFoundError, suggestion
from cbp.robot import Approximation, FloatArray, IntArray, RobotModel
from cbp.state import RobotState

__all__ = ["UNREAD_VISUAL_EXCESS", "RobotGeometry", "find_ignorable_pairs"]


log = logging.getLogger(__name__)

#: How far a link is taken to look larger than its collision shapes when its
#: visual meshes cannot be read [m] (the self-filter's reach before it was
#: measured from the shapes).
UNREAD_VISUAL_EXCESS = 0.03


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
                shape, hull = hull_shape(Path(obj.meshPath), np.asarray(obj.meshScale))
                if self.approximation == "capsule":
                    offset, radius, length = fit_capsule(np.asarray(hull.vertices))
                    shape = coal.Capsule(radius, length)
                    hull = primitive_mesh(shape)
                    placement = placement * offset
            else:
                shape = obj.geometry
                hull = primitive_mesh(shape)
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
                primitive_mesh(attached.shape),
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
                planes=transform_planes(face_planes(hull), placement),
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
                vertices = np.asarray(primitive_mesh(obj.geometry).vertices)
            frame = model.frames[obj.parentFrame]
            placement = frame.placement.inverse() * obj.placement
            in_frame = vertices.dot(placement.rotation.T) + placement.translation
            beyond = beyond_planes(in_frame, [own[s].planes for s in on_link])
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
        place_shapes(
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
