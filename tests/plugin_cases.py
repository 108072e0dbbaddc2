"""One valid example per registered plugin, for the generic tests.

Every type name in the task and constraint registries must have a case here:
``tests/test_registry.py`` checks that the two sets are equal, so a new plugin
cannot skip the Jacobian and contract checks.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from cbp.collision import (
    CollisionSettings,
    CollisionWorld,
    EnvironmentObject,
    PrimitiveEnvironment,
    RobotGeometry,
)
from cbp.plugin import Plugin
from cbp.plugins.constraints.contact_normals_constraint import (
    ContactNormalsConstraint,
    ContactParams,
)
from cbp.plugins.constraints.joint_acceleration_constraint import (
    JointAccelerationConstraint,
    JointAccelerationParams,
)
from cbp.plugins.constraints.joint_limits_constraint import (
    JointLimitsConstraint,
    JointLimitsParams,
)
from cbp.plugins.constraints.joint_velocity_constraint import (
    JointVelocityConstraint,
    JointVelocityParams,
)
from cbp.plugins.constraints.min_altitude_constraint import (
    MinAltitudeConstraint,
    MinAltitudeParams,
)
from cbp.plugins.constraints.no_roll_constraint import NoRollConstraint, NoRollParams
from cbp.plugins.constraints.obstacle_distance_constraint import (
    ObstacleDistanceConstraint,
    ObstacleDistanceParams,
)
from cbp.plugins.constraints.orbit_distance_constraint import (
    OrbitDistanceConstraint,
    OrbitDistanceParams,
)
from cbp.plugins.constraints.self_collision_constraint import SelfCollisionConstraint
from cbp.plugins.constraints.view_direction_constraint import (
    ViewDirectionConstraint,
    ViewDirectionParams,
)
from cbp.plugins.tasks.camera_velocity_task import (
    CameraVelocityParams,
    CameraVelocityTask,
)
from cbp.plugins.tasks.goal_pose_task import GoalPoseParams, GoalPoseTask
from cbp.plugins.tasks.joint_step_task import JointStepParams, JointStepTask
from cbp.plugins.tasks.posture_task import PostureParams, PostureTask
from cbp.robot import FloatArray, RobotModel
from cbp.state import RobotState

#: Robots every case runs on: a fixed arm, and bases where nq != nv.
ALL_ROBOTS = ("panda", "panda_planar", "panda_floating")

GOAL = pin.SE3(pin.rpy.rpyToMatrix(np.pi, 0.0, 0.3), np.array([0.4, 0.1, 0.5]))


@dataclass
class PluginCase:
    """How to build one plugin for the generic tests.

    Attributes:
        type_name: the registry name the case covers.
        build: makes the plugin for a robot.
        robots: the fixtures it runs on.
        accept: filter on sampled configurations (to avoid a singularity).
        atol: absolute tolerance of the finite-difference check.
    """

    type_name: str
    build: Callable[[RobotModel], Plugin[Any]]
    robots: tuple[str, ...] = ALL_ROBOTS
    accept: Callable[[RobotModel, FloatArray], bool] | None = None
    atol: float = 1e-6
    params: dict[str, Any] = field(default_factory=dict)


def _goal_pose(robot: RobotModel) -> GoalPoseTask:
    task = GoalPoseTask(GoalPoseParams(frame="panda_hand"), robot)
    task.set_target(GOAL.translation, GOAL.rotation)
    return task


def _away_from_pi(robot: RobotModel, q: FloatArray) -> bool:
    # log3 is singular at a rotation angle of pi: keep the hand's rotation error
    # below 2.8 rad so the finite differences do not straddle the branch cut.
    state = RobotState(robot, q)
    R = state.frame_rotation(robot.frame_id("panda_hand"))
    return bool(np.linalg.norm(pin.log3(R.dot(GOAL.rotation.T))) < 2.8)


_WORLDS: dict[int, CollisionWorld] = {}


def collision_world(robot: RobotModel) -> CollisionWorld:
    """A world per robot: obstacles around the Panda, a wide activation distance.

    Random configurations then have contacts.
    """
    world = _WORLDS.get(id(robot))
    if world is None:
        objects = [
            EnvironmentObject.primitive(
                "box",
                "box",
                (0.3, 0.3, 0.3),
                pin.SE3(np.eye(3), np.array([0.5, 0.0, 0.3])),
            ),
            EnvironmentObject.primitive(
                "ball", "sphere", (0.15,), pin.SE3(np.eye(3), np.array([0.0, 0.5, 0.6]))
            ),
            EnvironmentObject.primitive(
                "post",
                "cylinder",
                (0.1, 1.0),
                pin.SE3(np.eye(3), np.array([-0.4, -0.3, 0.5])),
            ),
        ]
        world = CollisionWorld(
            RobotGeometry(robot),
            PrimitiveEnvironment(objects),
            CollisionSettings(activation_distance=0.4, contacts_per_link=2),
        )
        _WORLDS[id(robot)] = world
    return world


def _with_world(plugin: ContactNormalsConstraint) -> ContactNormalsConstraint:
    plugin.attach_world(collision_world(plugin.robot))
    return plugin


def _has_contacts(self_pairs: bool) -> Callable[[RobotModel, FloatArray], bool]:
    def accept(robot: RobotModel, q: FloatArray) -> bool:
        contacts = collision_world(robot).contacts(RobotState(robot, q))
        return int(np.count_nonzero(contacts.is_self == self_pairs)) >= 3

    return accept


#: The orbit plugins run on the youBot (planar base: arm and base joints).
YOUBOT = ("youbot",)
OBJECT = (1.0, 0.2, 0.1)


def _camera_velocity(robot: RobotModel) -> CameraVelocityTask:
    task = CameraVelocityTask(CameraVelocityParams(), robot)
    task.set_input(np.array([0.1, -0.05]))
    return task


PLUGIN_CASES: list[PluginCase] = [
    PluginCase("camera_velocity", _camera_velocity, robots=YOUBOT),
    PluginCase(
        "min_altitude",
        lambda r: MinAltitudeConstraint(MinAltitudeParams(), r),
        robots=YOUBOT,
    ),
    PluginCase("no_roll", lambda r: NoRollConstraint(NoRollParams(), r), robots=YOUBOT),
    PluginCase(
        "obstacle_distance",
        lambda r: ObstacleDistanceConstraint(ObstacleDistanceParams(), r),
        robots=YOUBOT,
    ),
    PluginCase(
        "orbit_distance",
        lambda r: OrbitDistanceConstraint(OrbitDistanceParams(object=OBJECT), r),
        robots=YOUBOT,
    ),
    PluginCase(
        "view_direction",
        lambda r: ViewDirectionConstraint(ViewDirectionParams(object=OBJECT), r),
        robots=YOUBOT,
    ),
    PluginCase(
        "view_direction",
        lambda r: ViewDirectionConstraint(
            ViewDirectionParams(object=OBJECT, form="paper"), r
        ),
        robots=YOUBOT,
    ),
    PluginCase(
        "contact_normals",
        lambda r: _with_world(ContactNormalsConstraint(ContactParams(), r)),
        accept=_has_contacts(False),
    ),
    PluginCase("goal_pose", _goal_pose, accept=_away_from_pi),
    PluginCase(
        "joint_acceleration",
        lambda r: JointAccelerationConstraint(JointAccelerationParams(), r),
    ),
    PluginCase("joint_limits", lambda r: JointLimitsConstraint(JointLimitsParams(), r)),
    PluginCase("joint_step", lambda r: JointStepTask(JointStepParams(), r)),
    PluginCase(
        "joint_velocity", lambda r: JointVelocityConstraint(JointVelocityParams(), r)
    ),
    PluginCase("posture", lambda r: PostureTask(PostureParams(), r)),
    PluginCase(
        "self_collision",
        lambda r: _with_world(SelfCollisionConstraint(ContactParams(), r)),
        accept=_has_contacts(True),
    ),
]
