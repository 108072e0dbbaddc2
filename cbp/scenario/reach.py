# SPDX-License-Identifier: Apache-2.0
"""How far a fixed arm can reach: a sphere about its first joint no goal beyond gets.

Take a point on each joint's axis. A point on a revolute joint's axis does
not move when the joint turns, so it is fixed in the links on both sides of
it; two consecutive such points are both fixed in the link between their
joints, and the distance between them is the same in every configuration. So
is the distance from the last joint's point to the goal frame (both fixed in
the last link). Added up, from the first joint's point (fixed in the base),
they bound how far the goal frame can be from it (the triangle inequality),
whichever points are taken. The points are chosen to make the sum least (a
convex problem: a sum of distances, each affine in the points' positions
along their axes), where consecutive axes meet or come closest: the Panda's
shoulder, elbow and wrist, 0.858 m from shoulder to hand. The joint origins
themselves (the bound before) gave 0.99 m: the elbow's offset counted twice.

The bound ignores joint limits and collisions, so a goal beyond it is
certainly out of reach (a false alarm is never raised), and a goal within it
may still be out of reach.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.optimize import minimize

from cbp.collision.geometry import RobotGeometry
from cbp.robot import FloatArray, RobotModel
from cbp.state import RobotState

__all__ = ["Bounds", "Reach", "arm_reach", "point_reach", "reach_box"]

Bounds = tuple[FloatArray, FloatArray]
"""A box's lower and upper corners (3,) each [m]."""


@dataclass(frozen=True)
class Reach:
    """The sphere a fixed arm's goal frame stays in.

    Attributes:
        centre: a point on the arm's first joint's axis, world frame (3,) [m]
            (on the Panda: its shoulder, 0.333 m above the base).
        radius: the most the goal frame can be from it [m] (the module's
            docstring).
    """

    centre: FloatArray
    radius: float

    def distance(self, position: FloatArray) -> float:
        """How far ``position`` (world frame, [m]) is from :attr:`centre` [m]."""
        return float(np.linalg.norm(np.asarray(position, dtype=float) - self.centre))

    def beyond(self, position: FloatArray) -> str | None:
        """Why ``position`` is out of reach, or None when it may be within it."""
        distance = self.distance(position)
        if distance <= self.radius:
            return None
        return (
            f"{distance:.2f} m from the arm's first joint, beyond its reach "
            f"({self.radius:.2f} m, its links' lengths between their joints' axes)"
        )


def arm_reach(robot: RobotModel, q: FloatArray, frame: str) -> Reach | None:
    """The reach of ``robot``'s ``frame`` from its first joint's axis.

    Args:
        robot: the robot model.
        q: any configuration of it (the bound does not depend on it).
        frame: the frame that tracks the goal.

    Returns:
        None where no such bound holds: a base that moves, a frame on the base
        (no joint moves it), or a joint on the chain that is not revolute (a
        prismatic one changes its link's length).
    """
    model = robot.model
    frame_id = robot.frame_id(frame)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    position = data.oMf[frame_id].translation
    return point_reach(robot, q, model.frames[frame_id].parentJoint, position)


def point_reach(
    robot: RobotModel, q: FloatArray, joint: int, point: FloatArray
) -> Reach | None:
    """The reach of a point fixed on the link that ``joint`` moves.

    Args:
        robot: the robot model.
        q: the configuration at which ``point`` is given.
        joint: the joint that moves the point's link (its index in the model).
        point: where the point is at ``q``, world frame (3,) [m].

    Returns:
        None as :func:`arm_reach` says.
    """
    if robot.base != "fixed":
        return None
    model = robot.model
    chain = list(model.supports[joint])[1:]
    if not chain or any(model.joints[j].nv != 1 for j in chain):
        return None
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    origins, axes = [], []
    for j in chain:
        jacobian = pin.getJointJacobian(model, data, j, pin.ReferenceFrame.WORLD)
        column = jacobian[:, model.joints[j].idx_v]
        if np.linalg.norm(column[3:]) < 0.5:  # it translates: no fixed length
            return None
        origins.append(data.oMi[j].translation.copy())
        axes.append(column[3:] / np.linalg.norm(column[3:]))
    end = np.asarray(point, dtype=float)
    along = _points_on_axes(np.array(origins), np.array(axes), end)
    points = np.array(origins) + along[:, None] * np.array(axes)
    legs = np.vstack([np.diff(points, axis=0), end - points[-1]])
    return Reach(points[0].copy(), float(np.sum(np.linalg.norm(legs, axis=1))))


def reach_box(geometry: RobotGeometry, q: FloatArray) -> Bounds | None:
    """The box every robot shape stays in, whatever the configuration.

    Each shape's bounding sphere, about the reach of its centre
    (:func:`point_reach`; a shape on the base, where it is at ``q``), grown by
    the shapes' padding: the space the padded robot can ever hold. None for a
    robot whose base moves (or with a joint that is not revolute).

    Args:
        geometry: the robot's shapes (camera housings included, when mounted).
        q: any configuration.

    Returns:
        The lower and upper corners (3,) [m].
    """
    state = RobotState(geometry.robot, q)
    placed = geometry.world_shapes(state)
    lower = np.full(3, np.inf)
    upper = np.full(3, -np.inf)
    for s, shape in enumerate(geometry.shapes):
        centre, radius = placed.centres[s], float(placed.radii[s])
        if shape.joint_id > 0:
            reach = point_reach(geometry.robot, q, shape.joint_id, centre)
            if reach is None:
                return None
            centre, radius = reach.centre, radius + reach.radius
        lower = np.minimum(lower, centre - radius - geometry.padding)
        upper = np.maximum(upper, centre + radius + geometry.padding)
    if not geometry.shapes:
        return None
    return lower, upper


def _points_on_axes(
    origins: FloatArray, axes: FloatArray, end: FloatArray
) -> FloatArray:
    """Where along each axis (n,) [m] the points make the sum of legs least.

    Any answer gives a valid bound (the module's docstring); this one is the
    least found by a quasi-Newton method on a smoothed sum (a leg's length
    sqrt(|d|^2 + eps^2)), eps shrinking from 1 cm to a micrometre.
    """

    def total(t: FloatArray, eps: float) -> tuple[float, FloatArray]:
        points = origins + t[:, None] * axes
        legs = np.vstack([np.diff(points, axis=0), end - points[-1]])
        lengths = np.sqrt(np.sum(legs**2, axis=1) + eps**2)
        unit = legs / lengths[:, None]
        # Leg k runs from point k to point k + 1 (the last to the end).
        grad = -np.einsum("ij,ij->i", unit, axes)
        grad[1:] += np.einsum("ij,ij->i", unit[:-1], axes[1:])
        return float(np.sum(lengths)), grad

    t = np.zeros(len(origins))
    for eps in (1e-2, 1e-4, 1e-6):
        t = np.asarray(minimize(total, t, args=(eps,), jac=True, method="BFGS").x)
    return t
