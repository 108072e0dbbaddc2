# SPDX-License-Identifier: Apache-2.0
"""How far a fixed arm can reach: a sphere around its first joint no goal beyond gets.

The bound is the lengths of the chain's links added up, from the first joint's
origin to the goal frame: each is the distance between two consecutive joint
origins, which a revolute joint does not change, so no configuration puts the
frame farther from the first joint. It is an upper bound (the arm cannot bend
every link straight), so a goal beyond it is certainly out of reach, and a
goal within it may still be (a false alarm is never raised; a miss may be).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from cbp.robot import FloatArray, RobotModel
from cbp.state import RobotState

__all__ = ["Reach", "arm_reach"]


@dataclass(frozen=True)
class Reach:
    """The sphere a fixed arm's goal frame stays in.

    Attributes:
        centre: the arm's first joint, world frame (3,) [m].
        radius: the chain's link lengths added up, from there to the goal
            frame [m].
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
            f"({self.radius:.2f} m, its links' lengths added up)"
        )


def arm_reach(robot: RobotModel, q: FloatArray, frame: str) -> Reach | None:
    """The reach of ``robot``'s ``frame`` from its first joint.

    Args:
        robot: the robot model.
        q: any configuration of it (the links' lengths do not depend on it).
        frame: the frame that tracks the goal.

    Returns:
        None where no such bound holds: a base that moves, or a prismatic
        joint on the chain (its length changes with the joint).
    """
    if robot.base != "fixed":
        return None
    model = robot.model
    frame_id = robot.frame_id(frame)
    chain = list(model.supports[model.frames[frame_id].parentJoint])[1:]
    if not chain or any(
        "Prismatic" in model.joints[j].shortname()
        or model.joints[j].shortname().startswith("JointModelP")
        for j in chain
    ):
        return None
    state = RobotState(robot, q)
    points = [state.data.oMi[j].translation.copy() for j in chain]
    points.append(state.frame_position(frame_id))
    radius = float(sum(np.linalg.norm(b - a) for a, b in itertools.pairwise(points)))
    return Reach(np.array(points[0], dtype=float), radius)
