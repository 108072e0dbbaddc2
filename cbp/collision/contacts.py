# SPDX-License-Identifier: Apache-2.0
"""Contacts between robot shapes and obstacles or each other: one type for all.

Environments answer queries with a :class:`ContactSet` of obstacle contacts
(distances of the unpadded shapes); the collision world pads them, adds the self
contacts, and hands the set to the contact constraints and step validation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from cbp.collision.cell_kernels import spread_contacts
from cbp.robot import FloatArray, IntArray

__all__ = ["ContactRow", "ContactSet"]

#: ``other_shape`` of obstacle contacts: views of one read-only array of -1
#: (the sets' arrays are never modified; a view costs less than a new array).
_NO_OTHER = np.full(256, -1, dtype=np.intp)
_NO_OTHER.flags.writeable = False

#: One contact as a row: (shape, other shape or -1, point, other point, normal,
#: distance), the fields of :class:`ContactSet` (built from rows in one call).
ContactRow = tuple[int, int, FloatArray, FloatArray, FloatArray, float]


@dataclass
class ContactSet:
    """Contacts of one configuration, environment and self, in the world frame.

    From a collision world, distances are those of the padded shapes; from an
    environment's query, of the unpadded ones. The ``other`` side is an obstacle
    (``other_shape == -1``) or a second robot shape (self-collision); the normal
    points from the other side toward ``shape``, so moving ``shape``'s point along
    it increases the distance.

    Attributes:
        shape: robot shape index, (K,).
        other_shape: the second robot shape for self contacts, else -1, (K,).
        point: witness point on ``shape`` (unpadded surface), (K, 3).
        other_point: witness point on the other side, (K, 3).
        normal: unit normal from the other side toward ``shape``, (K, 3).
        distance: signed distance [m], negative when the shapes overlap (then
            its magnitude is the penetration depth), (K,).
        lead: how much nearer than the obstacle's present surface each
            contact is measured [m] (K,), or None: every contact where its
            obstacle is. An obstacle the cameras see moving is measured nearer
            by how far it may come over the look-ahead
            (:mod:`cbp.perception.moving`); the contact rows keep the arm out
            of that region, and step validation measures where the obstacle
            is (:attr:`present_penetration`).
    """

    shape: IntArray
    other_shape: IntArray
    point: FloatArray
    other_point: FloatArray
    normal: FloatArray
    distance: FloatArray
    lead: FloatArray | None = field(default=None, compare=False)
    _split: tuple[ContactSet, ContactSet] | None = field(
        default=None, repr=False, compare=False
    )
    #: How many obstacle contacts come first, all self contacts after them
    #: (-1: not known; the parts are then found by ``other_shape``).
    _obstacles: int = field(default=-1, repr=False, compare=False)

    @classmethod
    def empty(cls) -> ContactSet:
        """No contacts."""
        z = np.zeros(0, dtype=np.intp)
        return cls(
            z, z, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
        )

    @classmethod
    def concatenate(cls, sets: list[ContactSet]) -> ContactSet:
        """All contacts of several sets."""
        sets = [s for s in sets if len(s)]
        if not sets:
            return cls.empty()
        if len(sets) == 1:  # the arrays are shared, never modified
            one = sets[0]
            return cls(
                one.shape,
                one.other_shape,
                one.point,
                one.other_point,
                one.normal,
                one.distance,
                one.lead,
            )
        lead = None
        if any(s.lead is not None for s in sets):
            lead = np.concatenate(
                [np.zeros(len(s)) if s.lead is None else s.lead for s in sets]
            )
        shape, other_shape, point, other_point, normal, distance = (
            np.concatenate([getattr(s, f) for s in sets])
            for f in (
                "shape",
                "other_shape",
                "point",
                "other_point",
                "normal",
                "distance",
            )
        )
        return cls(shape, other_shape, point, other_point, normal, distance, lead)

    @classmethod
    def from_rows(cls, rows: list[ContactRow]) -> ContactSet:
        """Stack (shape, other shape, point, other point, normal, distance) rows."""
        if not rows:
            return cls.empty()
        shape, other_shape, point, other_point, normal, distance = zip(
            *rows, strict=True
        )
        return cls(
            np.array(shape, dtype=np.intp),
            np.array(other_shape, dtype=np.intp),
            np.array(point, dtype=float).reshape(-1, 3),
            np.array(other_point, dtype=float).reshape(-1, 3),
            np.array(normal, dtype=float).reshape(-1, 3),
            np.array(distance, dtype=float),
        )

    @classmethod
    def obstacles(
        cls,
        shape: IntArray,
        point: FloatArray,
        other_point: FloatArray,
        normal: FloatArray,
        distance: FloatArray,
    ) -> ContactSet:
        """Contacts with obstacles (``other_shape`` -1 throughout)."""
        n = len(shape)
        return cls(
            shape,
            _NO_OTHER[:n] if n <= len(_NO_OTHER) else np.full(n, -1, dtype=np.intp),
            point,
            other_point,
            normal,
            distance,
        )

    @classmethod
    def stack(
        cls,
        obstacles: ContactSet,
        padding: float,
        own: list[ContactRow] | ContactSet,
    ) -> ContactSet:
        """The obstacle contacts, then the self contacts, with both parts.

        Each field is built by one numpy call, and the parts are views of it.

        Args:
            obstacles: an environment's contacts, distances of the unpadded
                shapes.
            padding: subtracted from the obstacle distances [m].
            own: the self contacts, as rows or a set (distances already padded).
        """
        n = len(obstacles)
        fields: (
            tuple[IntArray, IntArray, FloatArray, FloatArray, FloatArray, FloatArray]
            | None
        ) = None
        if isinstance(own, ContactSet):
            if len(own):
                fields = (
                    own.shape,
                    own.other_shape,
                    own.point,
                    own.other_point,
                    own.normal,
                    own.distance,
                )
        elif own:
            columns = tuple(zip(*own, strict=True))
            fields = (
                np.array(columns[0], dtype=np.intp),
                np.array(columns[1], dtype=np.intp),
                np.array(columns[2], dtype=float).reshape(-1, 3),
                np.array(columns[3], dtype=float).reshape(-1, 3),
                np.array(columns[4], dtype=float).reshape(-1, 3),
                np.array(columns[5], dtype=float),
            )
        if fields is not None:
            i, j, point, other, normal, distance = fields
            arrays = (
                np.concatenate((obstacles.shape, i)),
                np.concatenate((obstacles.other_shape, j)),
                np.concatenate((obstacles.point, point)),
                np.concatenate((obstacles.other_point, other)),
                np.concatenate((obstacles.normal, normal)),
                np.concatenate((obstacles.distance - padding, distance)),
            )
        else:
            arrays = (
                obstacles.shape,
                obstacles.other_shape,
                obstacles.point,
                obstacles.other_point,
                obstacles.normal,
                obstacles.distance - padding,
            )
        # The parts are views of the same arrays (the set itself would be a cycle).
        shape, other_shape, point_, other_point, normal_, distance_ = arrays
        lead = obstacles.lead
        if lead is not None and len(shape) > n:
            lead = np.concatenate((lead, np.zeros(len(shape) - n)))

        def part(rows: slice) -> ContactSet:
            return cls(
                shape[rows],
                other_shape[rows],
                point_[rows],
                other_point[rows],
                normal_[rows],
                distance_[rows],
                None if lead is None else lead[rows],
            )

        return cls(
            shape,
            other_shape,
            point_,
            other_point,
            normal_,
            distance_,
            lead,
            _split=(part(slice(0, n)), part(slice(n, None))),
        )

    @classmethod
    def packed(
        cls, index: IntArray, floats: FloatArray, obstacles: int, count: int
    ) -> ContactSet:
        """Contacts a kernel wrote, obstacles first; both parts will be views.

        Args:
            index: (2, K): the shapes, then the other shapes (-1: obstacle).
            floats: (4, K, 3): points, other points, normals, then the
                distances in ``floats[3, :, 0]``.
            obstacles: how many contacts with obstacles come first.
            count: how many contacts in all.
        """
        return cls(
            index[0, :count],
            index[1, :count],
            floats[0, :count],
            floats[1, :count],
            floats[2, :count],
            floats[3, :count, 0],
            _obstacles=obstacles,
        )

    def select(self, mask: np.ndarray | slice) -> ContactSet:
        """The contacts where ``mask`` is true, at the given indices, or in a slice.

        A slice gives views of this set's arrays; the others, copies.
        """
        return ContactSet(
            self.shape[mask],
            self.other_shape[mask],
            self.point[mask],
            self.other_point[mask],
            self.normal[mask],
            self.distance[mask],
            None if self.lead is None else self.lead[mask],
        )

    @property
    def is_self(self) -> np.ndarray:
        """Which contacts are between two robot shapes."""
        return np.asarray(self.other_shape >= 0)

    def environment_part(self) -> ContactSet:
        """The contacts with obstacles (computed once per set)."""
        return self._parts()[0]

    def self_part(self) -> ContactSet:
        """The contacts between two robot shapes (computed once per set)."""
        return self._parts()[1]

    def _parts(self) -> tuple[ContactSet, ContactSet]:
        parts = self._split
        if parts is None:
            n = self._obstacles
            if n >= 0:
                parts = (self.select(slice(0, n)), self.select(slice(n, None)))
            else:
                is_self = self.is_self
                parts = (self.select(~is_self), self.select(is_self))
            self._split = parts
        return parts

    @property
    def penetration(self) -> float:
        """Deepest penetration of the padded shapes [m]; 0 when nothing overlaps.

        Infinite when a distance is NaN (a contact not measured).
        """
        return _penetration(self.distance)

    @property
    def present_penetration(self) -> float:
        """:attr:`penetration` with each obstacle where it is, not ahead (``lead``)."""
        if self.lead is None:
            return _penetration(self.distance)
        return _penetration(self.distance + self.lead)

    def __len__(self) -> int:
        """Number of contacts."""
        return int(self.shape.size)

    def keep_closest(
        self, per_shape: int, min_angle_deg: float, min_spacing: float
    ) -> ContactSet:
        """Up to ``per_shape`` contacts per shape, spread over directions.

        The closest first, then the next closest that differ from every kept one
        in normal (by ``min_angle_deg``) or position (by ``min_spacing``): a few
        contacts that span the directions the shape is blocked in, instead of
        one per voxel.
        """
        if len(self) == 0:
            return self
        if min_spacing <= 0.0 and np.bincount(self.shape).max() <= per_shape:
            return self  # nothing to drop (the common case for declared objects)
        order = np.lexsort((self.distance, self.shape))
        keep = np.empty(len(self), dtype=np.intp)
        count = spread_contacts(
            order,
            self.shape,
            self.normal,
            self.point,
            per_shape,
            math.cos(math.radians(min_angle_deg)),
            min_spacing * min_spacing,
            keep,
        )
        return self.select(keep[:count])


@numba.njit(cache=True, nogil=True)
def _penetration(distance: FloatArray) -> float:
    """max(0, -min(distance)) in one pass; 0 for none.

    Infinite when a distance is NaN: a contact that could not be measured
    counts as the deepest, so a step validated by it is refused (it had
    counted as none, as numpy's max(0, min(.)) dropped the NaN).
    """
    deepest = 0.0
    for d in distance:
        if math.isnan(d):
            return math.inf
        deepest = max(deepest, -d)
    return deepest


# Compiled (or loaded from numba's cache) on import, for contiguous distances
# and a kernel's strided column (two rows: a shorter one is flagged contiguous).
_penetration(np.zeros(1))
_penetration(np.zeros((2, 4))[:, 0])
