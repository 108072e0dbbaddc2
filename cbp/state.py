# SPDX-License-Identifier: Apache-2.0
"""RobotState: a configuration with its forward kinematics, computed once per step."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from cbp.robot import FloatArray, RobotModel

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class RobotState:
    """A configuration ``q`` and its kinematics, shared read-only by every plugin.

    :meth:`update` runs forward kinematics and the joint Jacobians once; frame
    placements and frame Jacobians are then read from pinocchio's data, and each frame
    Jacobian is computed at most once per update, however many plugins ask for it.

    All Jacobians are in the LOCAL_WORLD_ALIGNED frame: linear rows give the velocity
    of the frame's origin in world coordinates, angular rows the angular velocity in
    world coordinates, both per unit of tangent-space velocity (nv columns).

    Attributes:
        robot: the model.
        q: the configuration (nq), read-only.
        v: the joint velocity at ``q`` (nv) [rad/s or m/s], read-only: what the
            robot was last commanded, given to :meth:`cbp.engine.Engine.step`
            by executors that command velocities; zeros (at rest) otherwise.
            Plugins that bound the change of velocity read it.
        data: pinocchio data holding the kinematics of ``q``.
    """

    def __init__(self, robot: RobotModel, q: FloatArray | None = None) -> None:
        """Create the state, at ``q`` if given (else at the robot's neutral)."""
        self.robot = robot
        self.data = robot.model.createData()
        self._jacobians: dict[int, FloatArray] = {}
        # Per frame: its position and rotation in ``data`` (views, made once:
        # pinocchio updates them in place).
        self._frames: dict[int, tuple[FloatArray, FloatArray]] = {}
        self.q: FloatArray = np.empty(0)
        self._rest = _at_rest(robot.nv)
        self.v: FloatArray = self._rest
        self.update(robot.neutral() if q is None else q)

    def update(self, q: FloatArray) -> None:
        """Move to ``q`` (copied) and recompute the kinematics."""
        q = np.array(q, dtype=float)
        q.flags.writeable = False
        self.q = q
        model = self.robot.model
        pin.computeJointJacobians(model, self.data, q)
        pin.updateFramePlacements(model, self.data)
        self._jacobians.clear()
        self._joint_jacobians: FloatArray | None = None

    def set_velocity(self, v: FloatArray | None) -> None:
        """Set :attr:`v` (copied); None: at rest."""
        if v is None:
            self.v = self._rest  # read-only: shared by every step at rest
            return
        v = np.array(v, dtype=float)
        v.flags.writeable = False
        self.v = v

    def joint_jacobians(self) -> FloatArray:
        """Every joint's motion in the WORLD frame, pinocchio's ``data.J``, (6, nv).

        Column v is the spatial velocity, linear part first, at the world origin,
        of velocity coordinate v; a point p on a body moved by joint j has the
        linear Jacobian ``(J[:3] - [p]_x J[3:]) * robot.support[j]``. Computed by
        :meth:`update`; shared, do not modify.
        """
        J = self._joint_jacobians
        if J is None:
            J = self._joint_jacobians = np.array(self.data.J)
            J.flags.writeable = False
        return J

    def frame_position(self, frame_id: int) -> FloatArray:
        """Position of the frame's origin in the world [m], shape (3,).

        A view of :attr:`data`, which :meth:`update` rewrites: copy it to keep it.
        """
        return self._frame(frame_id)[0]

    def frame_rotation(self, frame_id: int) -> FloatArray:
        """Rotation matrix from the frame to the world, shape (3, 3).

        A view of :attr:`data`, which :meth:`update` rewrites: copy it to keep it.
        """
        return self._frame(frame_id)[1]

    def _frame(self, frame_id: int) -> tuple[FloatArray, FloatArray]:
        """The frame's position and rotation in :attr:`data` (views, made once)."""
        views = self._frames.get(frame_id)
        if views is None:
            placement = self.data.oMf[frame_id]
            views = np.asarray(placement.translation), np.asarray(placement.rotation)
            self._frames[frame_id] = views
        return views

    def frame_placement(self, frame_id: int) -> pin.SE3:
        """Placement of the frame in the world (a pinocchio SE3; do not modify)."""
        return self.data.oMf[frame_id]

    def frame_jacobian(self, frame_id: int) -> FloatArray:
        """Jacobian of the frame, LOCAL_WORLD_ALIGNED, shape (6, nv): linear first.

        The returned array is shared by every caller in this step: do not modify it.
        """
        J = self._jacobians.get(frame_id)
        if J is None:
            J = pin.getFrameJacobian(self.robot.model, self.data, frame_id, _LWA)
            J.flags.writeable = False
            self._jacobians[frame_id] = J
        return J

    def point_jacobian(self, frame_id: int, point: FloatArray) -> FloatArray:
        """Linear Jacobian (3, nv) of a point fixed on the frame's body.

        Args:
            frame_id: a frame of the body that carries the point.
            point: the point's current position in the world [m], shape (3,).

        The velocity of a point p of a body with origin o is v_o + ω × (p - o), so
        its Jacobian is J_lin - [p - o]_x J_ang, all world-aligned.
        """
        J = self.frame_jacobian(frame_id)
        offset = point - self.data.oMf[frame_id].translation
        return np.asarray(J[:3] - pin.skew(offset).dot(J[3:]))

    def __repr__(self) -> str:
        """Robot name and configuration."""
        return (
            f"RobotState({self.robot.name!r}, q={np.array2string(self.q, precision=3)})"
        )


def _at_rest(nv: int) -> FloatArray:
    """A read-only zero velocity of ``nv`` coordinates."""
    v = np.zeros(nv)
    v.flags.writeable = False
    return v
