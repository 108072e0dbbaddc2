"""Measuring the arm against one declared obstacle, for the obstacle tests."""

from __future__ import annotations

import numpy as np

from cbp.collision import (
    CollisionSettings,
    CollisionWorld,
    EnvironmentObject,
    PrimitiveEnvironment,
    RobotGeometry,
)
from cbp.scenario import Scenario
from cbp.scenario.scene import ObjectSpec


def unpadded_distance(
    scenario: Scenario, obj: ObjectSpec, t: float, q: np.ndarray
) -> float:
    """Distance from the unpadded arm at ``q`` to ``obj`` as it is at ``t`` [m]."""
    placement = obj.placement_at(t)
    shape = EnvironmentObject.primitive(obj.name, obj.shape, obj.size, placement)
    world = CollisionWorld(
        RobotGeometry(scenario.robot, padding=0.0),
        PrimitiveEnvironment([shape]),
        CollisionSettings(activation_distance=1.0, self_collision=False, padding=0.0),
    )
    contacts = world.check(q).contacts
    return float(contacts.distance.min()) if len(contacts) else np.inf
