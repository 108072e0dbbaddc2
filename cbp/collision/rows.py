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

from collections.abc import Sequence

import numba
import numpy as np
import pinocchio as pin

from cbp.collision.contacts import ContactSet
from cbp.collision.geometry import RobotGeometry
from cbp.robot import FloatArray, IntArray
from cbp.state import RobotState

__all__ = ["LatchedContacts"]

#: Lower bounds kept per :class:`LatchedContacts` (one per number of rows in use).
_KEPT_BOUNDS = 64


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
        self._frame_of_shape = [s.frame_id for s in geometry.shapes]
        joints = np.array([s.joint_id for s in geometry.shapes], dtype=np.intp)
        self._support = geometry.robot.support[joints]  # (shapes, nv)
        self._q: FloatArray | None = None
        # Both sides' points in their frames at the latch configuration, when a
        # configuration away from it is first evaluated.
        self._local: tuple[FloatArray, FloatArray] | None = None
        # The lower bounds by (active rows, safety distance), read-only: the
        # QP copies bounds only when they are another array than at its last
        # step (as a constraint's fixed limits).
        self._lower: dict[tuple[int, float], FloatArray] = {}
        self._upper = np.full(capacity, np.inf)
        self._upper.flags.writeable = False
        # Compile the rows (or load them from numba's cache) here, not in the
        # first control step: no contact, and arrays of the kinds a step passes.
        empty = ContactSet.empty()
        joint_jacobians = RobotState(geometry.robot).joint_jacobians()
        jacobian = np.zeros((capacity, geometry.robot.nv))
        self._jacobian_rows(
            empty, empty.point, empty.other_point, joint_jacobians, jacobian
        )
        # Distances as sets hold them: contiguous, or a kernel's strided column.
        # (Two rows: numpy flags a shorter strided column contiguous.)
        for distance in (empty.distance, np.zeros((2, 3))[:, 0]):
            latched_rows(
                _latched_arrays(empty, distance),
                self._support,
                joint_jacobians,
                np.zeros(capacity),
                jacobian,
            )

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

    def _at_latch(self, state: RobotState) -> bool:
        return state.q is self._q

    def value(self, state: RobotState) -> FloatArray:
        """f(q) for the active rows, zeros after them, shape (capacity,)."""
        out = np.empty(self.capacity)
        self.value_into(state, out)
        return out

    def value_into(self, state: RobotState, out: FloatArray) -> None:
        """Write :meth:`value` into ``out`` (capacity,)."""
        n, c = self.count, self._contacts
        out[:n] = c.distance
        out[n:] = 0.0
        if n and not self._at_latch(state):
            point, other = self._moved_points(state)
            # The other side's point is the latched one for an obstacle contact.
            move = (point - c.point) - (other - c.other_point)
            out[:n] += np.einsum("ij,ij->i", c.normal, move)

    def linearize_into(
        self, state: RobotState, value: FloatArray, jacobian: FloatArray
    ) -> None:
        """:meth:`value_into` and :meth:`jacobian_into` together.

        At the latch configuration (every engine step) in one compiled pass.
        """
        if not self._at_latch(state):
            self.value_into(state, value)
            self.jacobian_into(state, jacobian)
            return
        c = self._contacts
        latched_rows(
            _latched_arrays(c, c.distance),
            self._support,
            state.joint_jacobians(),
            value,
            jacobian,
        )

    def jacobian(self, state: RobotState) -> FloatArray:
        """n^T (J_p - J_p') for the active rows, zeros after, shape (capacity, nv)."""
        out = np.empty((self.capacity, state.robot.nv))
        self.jacobian_into(state, out)
        return out

    def jacobian_into(self, state: RobotState, out: FloatArray) -> None:
        """Write :meth:`jacobian` into ``out`` (capacity, nv)."""
        out.fill(0.0)
        if self.count:
            c = self._contacts
            point, other = (
                (c.point, c.other_point)
                if self._at_latch(state)
                else self._moved_points(state)
            )
            self._jacobian_rows(c, point, other, state.joint_jacobians(), out)

    def _jacobian_rows(
        self,
        contacts: ContactSet,
        point: FloatArray,
        other: FloatArray,
        joint_jacobians: FloatArray,
        out: FloatArray,
    ) -> None:
        """:func:`contact_jacobian_rows` of ``contacts``, their points at these."""
        contact_jacobian_rows(
            point,
            other,
            contacts.normal,
            contacts.shape,
            contacts.other_shape,
            self._support,
            joint_jacobians,
            out,
        )

    def bounds(self, safety_distance: float) -> tuple[FloatArray, FloatArray]:
        """Active rows: [safety_distance, inf); inactive rows: (-inf, inf).

        Read-only arrays, the same ones for the same number of active rows.
        """
        key = (self.count, safety_distance)
        lower = self._lower.get(key)
        if lower is None:
            if len(self._lower) >= _KEPT_BOUNDS:
                self._lower.clear()
            lower = np.full(self.capacity, -np.inf)
            lower[: self.count] = safety_distance
            lower.flags.writeable = False
            self._lower[key] = lower
        return lower, self._upper

    def _moved_points(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """Both sides' latched points at ``state``, moved with their frames, (n, 3).

        An obstacle contact's other point stays where it was latched.
        """
        c, frames = self._contacts, self._frame_of_shape
        if self._local is None:
            # In the frames at the latch configuration. Only needed away from it
            # (the Jacobian checker), so computed on demand.
            assert self._q is not None
            latched = RobotState(state.robot, self._q).data.oMf
            self._local = (
                _in_frames(latched, frames, c.shape, c.point, inverse=True),
                _in_frames(latched, frames, c.other_shape, c.other_point, inverse=True),
            )
        oMf = state.data.oMf
        point, other = self._local
        return (
            _in_frames(oMf, frames, c.shape, point),
            _in_frames(oMf, frames, c.other_shape, other),
        )


def _latched_arrays(
    contacts: ContactSet, distance: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, IntArray, IntArray]:
    """``contacts`` as :func:`latched_rows` takes them, with these distances."""
    c = contacts
    return (distance, c.point, c.other_point, c.normal, c.shape, c.other_shape)


def _in_frames(
    placements: Sequence[pin.SE3],
    frames: list[int],
    shapes: IntArray,
    points: FloatArray,
    *,
    inverse: bool = False,
) -> FloatArray:
    """Points (n, 3) moved by the frames of their shapes.

    From the frame to the world, or (``inverse``) from the world to the frame.
    A point of shape -1 (an obstacle) is kept as it is.
    """
    moved = [
        p
        if s < 0
        else (
            placements[frames[s]].actInv(p) if inverse else placements[frames[s]].act(p)
        )
        for s, p in zip(shapes.tolist(), points, strict=True)
    ]
    return np.array(moved, dtype=float).reshape(-1, 3)


@numba.njit(cache=True, nogil=True)
def contact_jacobian_rows(
    point: FloatArray,
    other_point: FloatArray,
    normal: FloatArray,
    shape: IntArray,
    other_shape: IntArray,
    support: FloatArray,
    J: FloatArray,
    out: FloatArray,
) -> None:
    """Write n^T (J_p - J_p') of every contact into the rows of ``out``.

    With J = [J_v; J_w] the joints' world motions (velocities at the world origin,
    :meth:`RobotState.joint_jacobians`), a point p moves at J_v - [p]_x J_w, so
    n^T J_p = [n; p x n]^T J, kept on the columns that move the point's body
    (``support`` of its shape). The other side (a second robot shape, where
    ``other_shape`` >= 0) moves the distance the other way.
    """
    nv = J.shape[1]
    for r in range(shape.size):
        nx, ny, nz = normal[r, 0], normal[r, 1], normal[r, 2]
        for side in range(2):
            if side == 0:
                s, p, sign = shape[r], point[r], 1.0
            else:
                s, p, sign = other_shape[r], other_point[r], -1.0
                if s < 0:
                    break
            px, py, pz = p[0], p[1], p[2]
            wx, wy, wz = py * nz - pz * ny, pz * nx - px * nz, px * ny - py * nx
            for c in range(nv):
                if support[s, c] != 0.0:
                    out[r, c] += sign * (
                        nx * J[0, c]
                        + ny * J[1, c]
                        + nz * J[2, c]
                        + wx * J[3, c]
                        + wy * J[4, c]
                        + wz * J[5, c]
                    )


@numba.njit(cache=True, nogil=True)
def latched_rows(
    contacts: tuple[FloatArray, FloatArray, FloatArray, FloatArray, IntArray, IntArray],
    support: FloatArray,
    J: FloatArray,
    value: FloatArray,
    jacobian: FloatArray,
) -> None:
    """The rows at the latch configuration: values and Jacobian rows, zeros after.

    ``contacts``: (distance, point, other point, normal, shape, other shape)
    of the latched contacts; the values are the distances, the Jacobian rows
    those of :func:`contact_jacobian_rows`.
    """
    distance, point, other_point, normal, shape, other_shape = contacts
    n = distance.size
    for r in range(value.size):
        value[r] = distance[r] if r < n else 0.0
    jacobian[:] = 0.0
    contact_jacobian_rows(
        point, other_point, normal, shape, other_shape, support, J, jacobian
    )
