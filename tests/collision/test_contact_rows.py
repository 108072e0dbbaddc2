"""Latched contact rows predict the distances a new query finds, to first order.

The finite-difference check compares a row's Jacobian with its own values; this
test compares the values with the collision world, so a wrong normal sign or a
point latched on the wrong link is caught too.
"""

from __future__ import annotations

import numpy as np
import pytest

from cbp.plugins.constraints.contact_normals_constraint import (
    ContactNormalsConstraint,
    ContactParams,
)
from cbp.plugins.constraints.self_collision_constraint import SelfCollisionConstraint
from cbp.state import RobotState
from cbp.testing import sample_configurations
from tests.plugin_cases import collision_world


@pytest.mark.parametrize("kind", [ContactNormalsConstraint, SelfCollisionConstraint])
def test_rows_predict_the_requeried_distances(robots, rng, kind) -> None:
    robot = robots["panda"]
    world = collision_world(robot)
    plugin = kind(ContactParams(max_contacts=32), robot)
    plugin.attach_world(world)
    checked = 0
    for q in sample_configurations(robot, rng, n=60, margin=0.1):
        state = RobotState(robot, q)
        plugin.prepare(state, 0.01)
        latched = plugin.contacts
        for _ in range(3):
            dq = rng.normal(size=robot.nv) * 2e-3
            moved = RobotState(robot, robot.integrate(q, dq))
            predicted = plugin.compute_value(moved)
            found = world.contacts(moved)
            for k in range(len(latched)):
                # The same pair of shapes, near the same place.
                same = np.flatnonzero(
                    (found.shape == latched.shape[k])
                    & (found.other_shape == latched.other_shape[k])
                    & (np.linalg.norm(found.point - latched.point[k], axis=1) < 0.02)
                )
                if same.size != 1:
                    continue
                actual = found.distance[same[0]]
                change = actual - latched.distance[k]
                if abs(change) < 1e-4:
                    continue
                # First order: the error is a small fraction of the change.
                assert abs(predicted[k] - actual) < 0.2 * abs(change) + 2e-5, (
                    k,
                    predicted[k],
                    actual,
                    latched.distance[k],
                )
                checked += 1
        if checked >= 40:
            break
    assert checked >= 20
