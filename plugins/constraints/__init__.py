# SPDX-License-Identifier: Apache-2.0
"""In-tree constraint plugins: the explicit, sorted registry ``CONSTRAINTS``."""

from cbp.plugin import AnyConstraint, Constraint
from cbp.registry import Registry

from .contact_normals_constraint import ContactNormalsConstraint
from .joint_acceleration_constraint import JointAccelerationConstraint
from .joint_limits_constraint import JointLimitsConstraint
from .joint_velocity_constraint import JointVelocityConstraint
from .min_altitude_constraint import MinAltitudeConstraint
from .no_roll_constraint import NoRollConstraint
from .obstacle_distance_constraint import ObstacleDistanceConstraint
from .orbit_distance_constraint import OrbitDistanceConstraint
from .self_collision_constraint import SelfCollisionConstraint
from .view_direction_constraint import ViewDirectionConstraint

__all__ = [
    "CONSTRAINTS",
    "ContactNormalsConstraint",
    "JointAccelerationConstraint",
    "JointLimitsConstraint",
    "JointVelocityConstraint",
    "MinAltitudeConstraint",
    "NoRollConstraint",
    "ObstacleDistanceConstraint",
    "OrbitDistanceConstraint",
    "SelfCollisionConstraint",
    "ViewDirectionConstraint",
]

#: Keep sorted by type name (checked at import).
CONSTRAINTS: Registry[AnyConstraint] = Registry(
    "constraint",
    Constraint,
    [
        ContactNormalsConstraint,
        JointAccelerationConstraint,
        JointLimitsConstraint,
        JointVelocityConstraint,
        MinAltitudeConstraint,
        NoRollConstraint,
        ObstacleDistanceConstraint,
        OrbitDistanceConstraint,
        SelfCollisionConstraint,
        ViewDirectionConstraint,
    ],
)
