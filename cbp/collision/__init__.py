# SPDX-License-Identifier: Apache-2.0
"""Collision checking with coal: robot geometry, environments, contacts, validation."""

from cbp.collision.contacts import ContactSet
from cbp.collision.environment import Environment
from cbp.collision.geometry import (
    LinkShape,
    PlacedShapes,
    RobotGeometry,
    find_ignorable_pairs,
)
from cbp.collision.map_environment import MetaballRefiner, OccupancyEnvironment
from cbp.collision.objects import EnvironmentObject, PrimitiveEnvironment
from cbp.collision.world import (
    CollisionSettings,
    CollisionWorld,
    StepCheck,
)

__all__ = [
    "CollisionSettings",
    "CollisionWorld",
    "ContactSet",
    "Environment",
    "EnvironmentObject",
    "LinkShape",
    "MetaballRefiner",
    "OccupancyEnvironment",
    "PlacedShapes",
    "PrimitiveEnvironment",
    "RobotGeometry",
    "StepCheck",
    "find_ignorable_pairs",
]
