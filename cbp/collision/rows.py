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
from cbp.robot import FloatArray
from cbp.state import RobotState

__all__ = ["LatchedContacts"]


class LatchedContacts:
    """Up to ``capacity`` contacts held fixed on the links for one step.

    Args:
        geometry: the robot shapes the contact indices refer to.
        capacity: the number of rows (fixed).
    """

    def __init__(self, geometry: RobotGeometry, capacity: int) -> None:
        """Start with no contact."""
        self.geometry = geometry
        self.capacity = capacity
        self.contacts = ContactSet.empty()
        self._frames: list[int] = []
        self._other_frames: list[int] = []
        self._local: FloatArray = np.zeros((0, 3))
        self._other_local: FloatArray = np.zeros((0, 3))
        self._start: FloatArray = np.zeros((0, 3))
        self._other_start: FloatArray = np.zeros((0, 3))

    @property
    def count(self) -> int:
        """Number of active rows."""
        return len(self.contacts)

    def latch(self, contacts: ContactSet, state: RobotState) -> None:
        """Keep the ``capacity`` closest contacts, fixed on their links at ``state``."""
        if len(contacts) > self.capacity:
            order = np.argsort(contacts.distance, kind="stable")[: self.capacity]
            contacts = contacts.select(order)
        shapes = self.geometry.shapes
        self.contacts = contacts
        self._frames = [shapes[i].frame_id for i in contacts.shape]
        self._other_frames = [
            shapes[j].frame_id if j >= 0 else -1 for j in contacts.other_shape
        ]
        self._start = contacts.point
        self._other_start = contacts.other_point
        self._local = self._to_local(state, self._frames, contacts.point)
        self._other_local = self._to_local(
            state, self._other_frames, contacts.other_point
        )

    @staticmethod
    def _to_local(
        state: RobotState, frames: list[int], points: FloatArray
    ) -> FloatArray:
        out = np.zeros_like(points)
        for k, fid in enumerate(frames):
            if fid >= 0:
                M = state.data.oMf[fid]
                out[k] = M.rotation.T.dot(points[k] - M.translation)
        return out

    def _moved(
        self,
        state: RobotState,
        frames: list[int],
        local: FloatArray,
        start: FloatArray,
    ) -> FloatArray:
        out = np.zeros_like(start)
        for k, fid in enumerate(frames):
            if fid >= 0:
                out[k] = state.data.oMf[fid].act(local[k]) - start[k]
        return out

    def value(self, state: RobotState) -> FloatArray:
        """f(q) for the active rows, zeros after them, shape (capacity,)."""
        out = np.zeros(self.capacity)
        n = self.count
        if n:
            c = self.contacts
            move = self._moved(state, self._frames, self._local, self._start)
            move -= self._moved(
                state, self._other_frames, self._other_local, self._other_start
            )
            out[:n] = c.distance + np.einsum("ij,ij->i", c.normal, move)
        return out

    def jacobian(self, state: RobotState) -> FloatArray:
        """n^T (J_p - J_p') for the active rows, zeros after, shape (capacity, nv)."""
        out = np.zeros((self.capacity, state.robot.nv))
        c = self.contacts
        for k in range(self.count):
            fid = self._frames[k]
            point = state.data.oMf[fid].act(self._local[k])
            row = c.normal[k].dot(state.point_jacobian(fid, point))
            other = self._other_frames[k]
            if other >= 0:
                point = state.data.oMf[other].act(self._other_local[k])
                row -= c.normal[k].dot(state.point_jacobian(other, point))
            out[k] = row
        return out

    def bounds(self, safety_distance: float) -> tuple[FloatArray, FloatArray]:
        """Active rows: [safety_distance, inf); inactive rows: (-inf, inf)."""
        lower = np.full(self.capacity, -np.inf)
        lower[: self.count] = safety_distance
        return lower, np.full(self.capacity, np.inf)
