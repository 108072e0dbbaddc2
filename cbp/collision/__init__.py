# SPDX-License-Identifier: Apache-2.0
"""Collision checking with coal: robot geometry, environments, contacts, validation."""

from cbp.collision.environment import (
    Environment,
    EnvironmentObject,
    Hits,
    MetaballRefiner,
    OccupancyEnvironment,
    PrimitiveEnvironment,
)
from cbp.collision.geometry import LinkShape, RobotGeometry, find_ignorable_pairs
from cbp.collision.world import (
    CollisionSettings,
    CollisionWorld,
    ContactSet,
    StepCheck,
)

__all__ = [
    "CollisionSettings",
    "CollisionWorld",
    "ContactSet",
    "Environment",
    "EnvironmentObject",
    "Hits",
    "LinkShape",
    "MetaballRefiner",
    "OccupancyEnvironment",
    "PrimitiveEnvironment",
    "RobotGeometry",
    "StepCheck",
    "find_ignorable_pairs",
]
