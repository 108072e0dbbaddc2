# SPDX-License-Identifier: Apache-2.0
"""Motions between checked configurations: how far the robot's shapes sweep.

A planner checks configurations; the robot moves along the straight joint-space
segments between them. Checking points a fixed joint step apart says nothing
about the space in between: near the shoulder 0.05 rad moves the hand 4-5 cm,
enough to pass through a shelf board and its padding. A bound on how far any
point of the robot moves along a segment closes that gap (the bound of
conservative advancement, Schwarzer, Saha and Latombe, IEEE T-RO 2005): a point
carried by revolute joint ``j`` moves at most ``r_j |dq_j|``, where ``r_j``
bounds its distance from the joint's axis, and one carried by a prismatic joint
``|dq_j|``; along a straight segment these add up. ``r_j`` is taken from the
kinematic chain, so it holds in every configuration: the lengths of the joint
placements from joint ``j`` to the shape's link, plus the reach of the shape's
bounding sphere from that link's joint.

Configurations checked with the links padded by ``p``, and at most ``p`` apart
by that bound, keep every point of the unpadded robot at least ``p / 2`` from
the obstacles in between (each point is within half the bound of one of the
two checked configurations): :meth:`SweepBound.between` gives those
configurations.
"""

from __future__ import annotations

import math

import numpy as np

from cbp.collision.geometry import RobotGeometry
from cbp.robot import FloatArray

__all__ = ["SweepBound"]

#: Joint kinds by pinocchio's short names (axis-aligned, unaligned, unbounded).
_REVOLUTE = {
    "JointModelRX",
    "JointModelRY",
    "JointModelRZ",
    "JointModelRevoluteUnaligned",
}
_PRISMATIC = {
    "JointModelPX",
    "JointModelPY",
    "JointModelPZ",
    "JointModelPrismaticUnaligned",
}


class SweepBound:
    """How far any point of a robot's shapes moves along a joint-space segment.

    Args:
        geometry: the robot's collision shapes (attachments included); its
            robot must have revolute and prismatic joints only (the executors
            that plan joint-space paths drive fixed-base arms).

    Raises:
        ValueError: a joint of another kind (a planar or floating base).
    """

    def __init__(self, geometry: RobotGeometry) -> None:
        """Bound each joint's reach over the shapes it carries."""
        model = geometry.robot.model
        reach = np.zeros(model.nv)
        per_joint = np.zeros(model.njoints)
        for shape in geometry.shapes:
            frame = model.frames[shape.frame_id]
            # The shape's farthest point from its joint, then up the chain.
            span = (
                float(np.linalg.norm(frame.placement.act(shape.centre))) + shape.radius
            )
            j = shape.joint_id
            while j > 0:
                per_joint[j] = max(per_joint[j], span)
                span += float(np.linalg.norm(model.jointPlacements[j].translation))
                j = model.parents[j]
        for j in range(1, model.njoints):
            joint = model.joints[j]
            kind = joint.shortname()
            if kind in _REVOLUTE:
                reach[joint.idx_v] = per_joint[j]
            elif kind in _PRISMATIC:
                reach[joint.idx_v] = 1.0
            else:
                raise ValueError(
                    f"joint {model.names[j]!r} is a {kind}: motions are bounded "
                    "for revolute and prismatic joints only"
                )
        self.reach = reach
        """Per joint: how far a shape's point moves per unit of it [m/rad, m/m]."""

    def distance(self, a: FloatArray, b: FloatArray) -> float:
        """An upper bound on how far any point moves from ``a`` to ``b`` [m]."""
        return float(self.reach.dot(np.abs(np.asarray(b) - np.asarray(a))))

    def segments(self, a: FloatArray, b: FloatArray, step: float) -> int:
        """How many equal parts of at most ``step`` [m] (by :meth:`distance`)."""
        return max(1, math.ceil(self.distance(a, b) / step))

    def between(self, a: FloatArray, b: FloatArray, step: float) -> FloatArray:
        """Configurations strictly between ``a`` and ``b``, at most ``step`` apart.

        Evenly spaced on the segment, so that consecutive configurations (and
        ``a`` and ``b`` at the ends) are at most ``step`` [m] apart by
        :meth:`distance`; none when ``a`` and ``b`` already are.
        """
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        n = self.segments(a, b, step)
        fractions = np.arange(1, n)[:, None] / n
        return a + fractions * (b - a)
