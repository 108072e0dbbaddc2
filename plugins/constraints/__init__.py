# SPDX-License-Identifier: Apache-2.0
"""In-tree constraint plugins: the explicit, sorted registry ``CONSTRAINTS``."""

from cbp.plugin import AnyConstraint, Constraint
from cbp.registry import Registry

from .contact_normals_constraint import ContactNormalsConstraint
from .joint_limits_constraint import JointLimitsConstraint
from .joint_velocity_constraint import JointVelocityConstraint
from .self_collision_constraint import SelfCollisionConstraint

__all__ = [
    "CONSTRAINTS",
    "ContactNormalsConstraint",
    "JointLimitsConstraint",
    "JointVelocityConstraint",
    "SelfCollisionConstraint",
]

#: Keep sorted by type name (checked at import).
CONSTRAINTS: Registry[AnyConstraint] = Registry(
    "constraint",
    Constraint,
    [
        ContactNormalsConstraint,
        JointLimitsConstraint,
        JointVelocityConstraint,
        SelfCollisionConstraint,
    ],
)
