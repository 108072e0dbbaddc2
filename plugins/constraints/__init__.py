# SPDX-License-Identifier: Apache-2.0
"""In-tree constraint plugins: the explicit, sorted registry ``CONSTRAINTS``."""

from cbp.plugin import AnyConstraint, Constraint
from cbp.registry import Registry

from .joint_limits_constraint import JointLimitsConstraint
from .joint_velocity_constraint import JointVelocityConstraint

__all__ = ["CONSTRAINTS", "JointLimitsConstraint", "JointVelocityConstraint"]

#: Keep sorted by type name (checked at import).
CONSTRAINTS: Registry[AnyConstraint] = Registry(
    "constraint", Constraint, [JointLimitsConstraint, JointVelocityConstraint]
)
