# SPDX-License-Identifier: Apache-2.0
"""Declared obstacles: coal shapes at world placements, the ground truth.

Queries measure exact distances for the (shape, object) pairs that a compiled
broad phase keeps (:mod:`cbp.collision.broad`): in the same compiled pass
(:mod:`cbp.collision.convex_kernels`, GJK and EPA) by default, or with coal
called from Python per pair (``collision.narrow_phase: coal``). Non-convex
meshes are measured by coal either way.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
from scipy.spatial import cKDTree

from cbp.collision.broad import near_objects
from cbp.collision.contacts import ContactRow, ContactSet
from cbp.collision.convex_kernels import (
    Obstacles,
    compile_convex_kernels,
    contact_buffers,
    declared_contacts,
    fields,
    obstacle_contacts,
    pack_shapes,
    packed_robot,
    placed_robot,
)
from cbp.collision.environment import (
    Environment,
    NarrowPhase,
    WholeQuery,
    signed_distance,
)
from cbp.collision.environment_object import EnvironmentObject
from cbp.collision.geometry import LinkShape, PlacedShapes, ShapePlacements
from cbp.collision.shape_table import compile_kernels
from cbp.robot import FloatArray, IntArray

__all__ = ["TREE_MIN_OBJECTS", "Approach", "EnvironmentObject", "PrimitiveEnvironment"]


TREE_MIN_OBJECTS = 32768
"""Above this many declared objects, a k-d tree picks those near the robot first.
Below it the compiled broad phase tests each object against the box around the
robot, which costs less (4,000 far objects add 4 us to a query; the tree query
alone takes 14 us)."""


@dataclass(frozen=True)
class Approach:
    """A moving object's nearest contact with the robot, and how fast it comes.

    Attributes:
        name: the object's name.
        shape: the robot shape it comes nearest to.
        ahead: their distance with the object where it will be after the
            look-ahead (unpadded shapes) [m].
        closing: how fast it comes at that shape, along the contact normal [m/s].
        point: the witness point on the robot shape (world) [m], (3,).
        normal: the unit normal from the object toward the shape, (3,).
    """

    name: str
    shape: int
    ahead: float
    closing: float
    point: FloatArray
    normal: FloatArray


class PrimitiveEnvironment(Environment):
    """Declared objects (ground truth), with a bounding-box broad phase.

    Only the (shape, object) pairs whose bounding sphere and box are within the
    margin reach coal, so the cost grows with the objects near the robot.

    With a ``look_ahead`` [s], an object that moves (its ``velocity``) is
    measured where it will be by then, to first order: a contact's distance is
    less the object's approach along the contact normal over that time,
    d - max(0, n . v) t_ahead, with the normal n pointing from the object toward
    the robot. An executor that plans now for a motion the robot
    makes later sets it to how long its plan runs (the trajectory executors: two
    command periods), so that the plan keeps clear of the object as it comes.
    An object moving away is measured where it is: the prediction never lets
    the robot nearer than the object's present position allows.

    Args:
        objects: the declared objects, where they are now.
        look_ahead: how far ahead moving objects are measured [s] (>= 0).
    """

    def __init__(
        self, objects: list[EnvironmentObject], look_ahead: float = 0.0
    ) -> None:
        """Index the objects' bounding boxes (swept over the look-ahead)."""
        if not look_ahead >= 0.0:
            raise ValueError(f"look_ahead must be >= 0 s, got {look_ahead}")
        self.objects = list(objects)
        self.look_ahead = float(look_ahead)
        #: Each object's displacement over the look-ahead [m], (n, 3).
        self._ahead = (
            np.array([o.velocity for o in objects], dtype=float).reshape(-1, 3)
            * self.look_ahead
        )
        self._moving = bool(np.any(self._ahead))
        lower = np.array([o.lower for o in objects]).reshape(-1, 3)
        upper = np.array([o.upper for o in objects]).reshape(-1, 3)
        self._lower = np.minimum(lower, lower + self._ahead)
        self._upper = np.maximum(upper, upper + self._ahead)
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
        self._packed = pack_shapes([o.shape for o in objects])
        self._fields = fields(self._packed)
        self._frames = np.array(
            [o.placement.homogeneous for o in objects], dtype=float
        ).reshape(-1, 4, 4)
        #: Per robot shapes (by their list's identity): (the list, which
        #: (shape, object) pairs are wanted contacts, left out, and where each
        #: pair's GJK starts next (n, m, 5)).
        self._skips: dict[int, tuple[list[LinkShape], np.ndarray, FloatArray]] = {}
        #: The last shapes and margin of :meth:`query_with_self`, with its
        #: objects as the kernel takes them.
        self._kernel_arguments: tuple[list[LinkShape], float, Obstacles] | None = None

    def prepare(self, shapes: list[LinkShape], margin: float) -> None:
        """Compile the kernels (once per process), pack the shapes."""
        del margin
        compile_kernels()
        compile_convex_kernels()
        packed_robot(shapes)
        self._skip(shapes)

    def _skip(self, shapes: list[LinkShape]) -> tuple[np.ndarray, FloatArray]:
        """Which (shape, object) pairs are wanted contacts, and where they start.

        (n, m) booleans, and each pair's GJK start (n, m, 5), the ``guess`` of
        :func:`~cbp.collision.convex_kernels.pair_distance`.
        """
        found = self._skips.get(id(shapes))
        if found is None or found[0] is not shapes:
            skip = np.array(
                [[s.link in o.allow_contact for o in self.objects] for s in shapes],
                dtype=np.bool_,
            ).reshape(len(shapes), len(self.objects))
            guess = np.zeros((len(shapes), len(self.objects), 5))
            if len(self._skips) >= 4:
                self._skips.clear()
            found = self._skips[id(shapes)] = (shapes, skip, guess)
        return found[1], found[2]

    def _kernel_objects(
        self, candidates: IntArray, shapes: list[LinkShape], margin: float
    ) -> Obstacles:
        """These objects as the compiled queries take them (:data:`Obstacles`).

        Their swept bounds, the ``candidates``, their placements and packed
        shapes, the wanted contacts and GJK starts of ``shapes``, their
        displacements, whether any moves, and ``margin``.
        """
        return (
            self._lower,
            self._upper,
            candidates,
            self._frames,
            self._fields,
            *self._skip(shapes),
            self._ahead,
            self._moving,
            float(margin),
        )

    def query(
        self,
        robot: PlacedShapes,
        margin: float,
        per_shape: int,
        narrow_phase: NarrowPhase = "compiled",
    ) -> ContactSet:
        """Exact distances of the candidate pairs; one contact per pair.

        Candidates: the objects whose bounding box is within ``margin`` of a
        shape's bounding sphere and (given ``halves``) of its box.
        """
        if not self.objects:
            return ContactSet.empty()
        candidates = self._near_robot(robot.centres, robot.radii, margin)
        if not candidates.size:
            return ContactSet.empty()
        if narrow_phase == "compiled":
            contacts = self._compiled(robot, candidates, margin)
        else:
            contacts = self._coal(robot, candidates, margin)
        if len(contacts) <= per_shape:  # no shape can have too many
            return contacts
        return contacts.keep_closest(per_shape, min_angle_deg=0.0, min_spacing=0.0)

    def approaches(self, robot: PlacedShapes, margin: float) -> list[Approach]:
        """How near each moving object comes to the robot, and how fast.

        Per moving object within ``margin`` of a shape (measured where it will
        be after the look-ahead): its nearest contact, where it will be, and
        its velocity's component toward the robot along that contact's normal.
        Objects at rest are left out.
        """
        out: list[Approach] = []
        if not self._moving:
            return out
        for k in np.flatnonzero(np.any(self._ahead != 0.0, axis=1)):
            contacts = self._compiled(robot, np.array([k], dtype=np.intp), margin)
            if not len(contacts):
                continue
            i = int(np.argmin(contacts.distance))
            velocity = self.objects[k].velocity
            closing = max(float(contacts.normal[i] @ velocity), 0.0)
            out.append(
                Approach(
                    self.objects[k].name,
                    int(contacts.shape[i]),
                    float(contacts.distance[i]),
                    closing,
                    contacts.point[i].copy(),
                    contacts.normal[i].copy(),
                )
            )
        return out

    def query_with_self(self, whole: WholeQuery) -> ContactSet | None:
        """The whole query in one compiled pass (:func:`declared_contacts`).

        None for scenes so large that a k-d tree picks the objects first, and
        for a query of some shapes' obstacle contacts only (``whole.moving``).
        """
        if len(self.objects) > TREE_MIN_OBJECTS or whole.moving is not None:
            return None
        frames, table, shapes, margin, per_shape, padding, self_margin, self_padding = (
            whole[:8]
        )
        candidates = self._all
        capacity = len(frames) * len(candidates) + len(table.first)
        index, floats, left = contact_buffers(capacity)
        # The objects as the kernel takes them, made once per shapes and margin
        # (this environment's objects do not change).
        made = self._kernel_arguments
        if made is None or made[0] is not shapes or made[1] != margin:
            objects = self._kernel_objects(candidates, shapes, margin)
            made = self._kernel_arguments = (shapes, margin, objects)
        obstacles, own, missed, missed_own, most = declared_contacts(
            frames,
            table.bounds,
            made[2],
            float(padding),
            table.pairs(float(self_margin), float(self_padding)),
            index,
            floats,
            left,
        )
        contacts = ContactSet.packed(index, floats, obstacles, obstacles + own)
        if not (missed or missed_own or most > per_shape):
            return contacts
        # Rare: pairs for coal, or more contacts than a shape may keep.
        found = contacts.environment_part()
        own_set = contacts.self_part()
        if missed or missed_own:
            placements = ShapePlacements([pin.SE3(M) for M in frames])
        if missed:
            placed = PlacedShapes(
                shapes, placements, table.centres, table.radii, table.halves
            )
            rows = self._measure(
                placed, left[0, :missed].tolist(), left[1, :missed].tolist(), margin
            )
            found = ContactSet.concatenate(
                [found, _padded(ContactSet.from_rows(rows), padding)]
            )
        if missed_own:
            rows = []
            for k in left[1, missed : missed + missed_own].tolist():
                i, j = int(table.first[k]), int(table.second[k])
                d, point, other, normal = signed_distance(
                    shapes[j].shape,
                    placements[j],
                    shapes[i].shape,
                    placements[i],
                    self._request,
                    self._result,
                )
                if d < self_margin:
                    rows.append((i, j, point, other, normal, d))
            own_set = ContactSet.concatenate(
                [own_set, _padded(ContactSet.from_rows(rows), self_padding)]
            )
        if len(found) > per_shape:
            found = found.keep_closest(per_shape, min_angle_deg=0.0, min_spacing=0.0)
        return ContactSet.stack(found, 0.0, own_set)

    def _compiled(
        self, robot: PlacedShapes, candidates: IntArray, margin: float
    ) -> ContactSet:
        """The candidates' contacts in one compiled pass (coal for meshes)."""
        capacity = len(robot.centres) * len(candidates)
        index = np.empty((2, capacity), dtype=np.intp)
        floats = np.empty((4, capacity, 3))
        missed = np.empty((2, capacity), dtype=np.intp)
        count, left = obstacle_contacts(
            placed_robot(robot),
            self._kernel_objects(candidates, robot.shapes, margin),
            index,
            floats,
            missed,
        )
        contacts = ContactSet.obstacles(
            index[0, :count],
            floats[0, :count],
            floats[1, :count],
            floats[2, :count],
            floats[3, :count, 0],
        )
        if not left:
            return contacts
        rows = self._measure(
            robot, missed[0, :left].tolist(), missed[1, :left].tolist(), margin
        )
        return ContactSet.concatenate([contacts, ContactSet.from_rows(rows)])

    def _coal(
        self, robot: PlacedShapes, candidates: IntArray, margin: float
    ) -> ContactSet:
        """The candidates' contacts, coal called from Python per pair."""
        centres, radii, halves = robot.centres, robot.radii, robot.halves
        shape_index, object_index = near_objects(
            centres, halves, radii, self._lower, self._upper, candidates, margin
        )
        pairs = [
            (i, k)
            for i, k in zip(shape_index.tolist(), object_index.tolist(), strict=True)
            if not (
                self.objects[k].allow_contact
                and robot.shapes[i].link in self.objects[k].allow_contact
            )  # wanted contact
        ]
        return ContactSet.from_rows(
            self._measure(robot, [i for i, _ in pairs], [k for _, k in pairs], margin)
        )

    def _measure(
        self, robot: PlacedShapes, shapes: list[int], objects: list[int], margin: float
    ) -> list[ContactRow]:
        """Coal's contacts of the pairs (shapes[p], objects[p]) nearer than margin."""
        rows: list[ContactRow] = []
        request, result = self._request, self._result
        for i, k in zip(shapes, objects, strict=True):
            obj = self.objects[k]
            d, point, other, normal = signed_distance(
                obj.shape,
                obj.placement,
                robot.shapes[i].shape,
                robot.placements[i],
                request,
                result,
            )
            if self._moving:  # the object's approach over the look-ahead
                d -= max(float(normal.dot(self._ahead[k])), 0.0)
            if d < margin:
                rows.append((i, -1, point, other, normal, d))
        return rows

    def collision_objects(self) -> list[tuple[str, coal.CollisionGeometry, pin.SE3]]:
        """Every declared object."""
        return [(o.name, o.shape, o.placement) for o in self.objects]

    def allowed_contacts(self) -> list[frozenset[str]]:
        """Per collision object, the robot links that may touch it."""
        return [o.allow_contact for o in self.objects]

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


def _padded(contacts: ContactSet, padding: float) -> ContactSet:
    """``contacts`` with ``padding`` subtracted from their distances."""
    return dataclasses.replace(contacts, distance=contacts.distance - padding)
