# SPDX-License-Identifier: Apache-2.0
r"""Contact rows shared by the contact constraints: contacts latched on the links.

At the start of a step a contact constraint latches the closest contacts: each is a
point fixed on a robot link (and, for self-collision, a second point fixed on
another link), a world normal :math:`n` and the signed distance :math:`d_0` found
by the query. Until the next step the contact pair is held fixed and the distance
is continued to first order in the motion of the points:

.. math:: f(q) = d_0 + n^T \big( (p(q) - p(q_0)) - (p'(q) - p'(q_0)) \big)

so :math:`f(q_0) = d_0` and :math:`\partial f / \partial q = n^T (J_p - J_{p'})`,
the Jacobian of eq. 5 of the CAT paper. Rows beyond the contacts found are
inactive: zero, with infinite bounds, so the QP keeps one shape.
"""

from __future__ import annotations

import numpy as np

from cbp.collision.geometry import RobotGeometry
from cbp.collision.world import ContactSet
from cbp.robot import FloatArray, IntArray
from cbp.state import RobotState

__all__ = ["LatchedContacts"]


class LatchedContacts:
    """Up to ``capacity`` contacts held fixed on the links for one step.

    Args:
        geometry: the robot shapes the contact indices refer to.
        capacity: the number of rows (fixed).

    The engine evaluates the rows at the configuration they were latched at,
    where the points are the contacts' own witness points and the value is the
    distance found; other configurations (the Jacobian checker's) move the
    points with their links.
    """

    def __init__(self, geometry: RobotGeometry, capacity: int) -> None:
        """Start with no contact."""
        self.geometry = geometry
        self.capacity = capacity
        self._contacts = ContactSet.empty()
        self._count = 0
        self._frame_of_shape = np.array([s.frame_id for s in geometry.shapes])
        joints = np.array([s.joint_id for s in geometry.shapes], dtype=np.intp)
        self._support = geometry.robot.support[joints]  # (shapes, nv)
        self._q: FloatArray | None = None
        # Every point that moves a row: the robot points of the n contacts, then
        # the other side's points of the self contacts (rows ``_other_rows``),
        # each with the normal signed so that its motion along it adds distance.
        self._shapes: IntArray = np.zeros(0, dtype=np.intp)
        self._frames: list[int] = []  # the points' frames, when first needed
        self._point_support: FloatArray = np.zeros((0, geometry.robot.nv))
        self._other_rows: slice | IntArray | None = None
        self._points: FloatArray = np.zeros((0, 3))
        self._normals: FloatArray = np.zeros((0, 3))
        self._local: FloatArray | None = None
        self._lower = np.full(capacity, -np.inf)
        self._upper = np.full(capacity, np.inf)

    @property
    def contacts(self) -> ContactSet:
        """The latched contacts (set by :meth:`latch`)."""
        return self._contacts

    @property
    def count(self) -> int:
        """Number of active rows."""
        return self._count

    def latch(self, contacts: ContactSet, state: RobotState) -> None:
        """Keep the ``capacity`` closest contacts, fixed on their links at ``state``."""
        if len(contacts) > self.capacity:
            order = np.argsort(contacts.distance, kind="stable")[: self.capacity]
            contacts = contacts.select(order)
        self._contacts = contacts
        self._count = len(contacts)
        self._q = state.q
        self._local = None
        is_self = contacts.other_shape >= 0
        if not is_self.any():  # obstacle contacts: the robot points alone
            self._other_rows = None
            shapes = contacts.shape
            self._points, self._normals = contacts.point, contacts.normal
        else:
            # Self contacts (the self-collision constraint's are all of them):
            # whole arrays where every row has a second point, else its rows.
            other: slice | IntArray = (
                slice(0, len(contacts)) if is_self.all() else np.flatnonzero(is_self)
            )
            self._other_rows = other
            shapes = np.concatenate([contacts.shape, contacts.other_shape[other]])
            self._points = np.concatenate([contacts.point, contacts.other_point[other]])
            self._normals = np.concatenate([contacts.normal, -contacts.normal[other]])
        self._shapes = shapes
        self._point_support = self._support[shapes]

    def _at_latch(self, state: RobotState) -> bool:
        return state.q is self._q

    def _add_rows(self, out: FloatArray, per_point: FloatArray) -> None:
        """Sum per-point terms into the contact rows: robot side, then other side."""
        n = self.count
        out[:n] = per_point[:n]
        if self._other_rows is not None:
            out[self._other_rows] += per_point[n:]

    def value(self, state: RobotState) -> FloatArray:
        """f(q) for the active rows, zeros after them, shape (capacity,)."""
        out = np.zeros(self.capacity)
        n = self.count
        if n and not self._at_latch(state):
            move = self._moved_points(state) - self._points
            self._add_rows(out, np.einsum("ij,ij->i", self._normals, move))
        out[:n] += self._contacts.distance
        return out

    def jacobian(self, state: RobotState) -> FloatArray:
        """n^T (J_p - J_p') for the active rows, zeros after, shape (capacity, nv)."""
        out = np.zeros((self.capacity, state.robot.nv))
        if self.count:
            points = (
                self._points if self._at_latch(state) else self._moved_points(state)
            )
            self._add_rows(out, self._normal_jacobians(state, points))
        return out

    def bounds(self, safety_distance: float) -> tuple[FloatArray, FloatArray]:
        """Active rows: [safety_distance, inf); inactive rows: (-inf, inf).

        The arrays are this object's own, rewritten by the next call.
        """
        lower = self._lower
        lower[: self.count] = safety_distance
        lower[self.count :] = -np.inf
        return lower, self._upper

    def _moved_points(self, state: RobotState) -> FloatArray:
        """The latched points at ``state``, moved with their frames, (k, 3)."""
        if self._local is None:
            # In the frames at the latch configuration: R^T (p - o). Only needed
            # away from it (the Jacobian checker), so computed on demand.
            assert self._q is not None
            oMf = RobotState(state.robot, self._q).data.oMf
            self._frames = self._frame_of_shape[self._shapes].tolist()
            self._local = np.array(
                [
                    oMf[f].rotation.T.dot(p - oMf[f].translation)
                    for f, p in zip(self._frames, self._points, strict=True)
                ]
            ).reshape(-1, 3)
        oMf = state.data.oMf
        return np.array(
            [oMf[f].act(p) for f, p in zip(self._frames, self._local, strict=True)]
        ).reshape(-1, 3)

    def _normal_jacobians(self, state: RobotState, points: FloatArray) -> FloatArray:
        """n^T J_p for every point, (k, nv), from the joints' world Jacobians.

        With J = [J_v; J_w] the world-frame joint motions (velocities at the world
        origin), a point p moves at J_v - [p]_x J_w, so n^T J_p = [n; p x n]^T J,
        kept on the columns that move the point's body: one product for all.
        """
        # The six weights per point in floats: a handful of products each, where
        # numpy calls (np.cross: 15 us) cost more.
        weights = np.array(
            [
                (nx, ny, nz, py * nz - pz * ny, pz * nx - px * nz, px * ny - py * nx)
                for (px, py, pz), (nx, ny, nz) in zip(
                    points.tolist(), self._normals.tolist(), strict=True
                )
            ]
        ).reshape(-1, 6)
        rows = weights.dot(state.joint_jacobians())
        rows *= self._point_support
        return rows  # type: ignore[no-any-return]
