"""The shapes' placements computed from q agree with pinocchio's."""

from __future__ import annotations

import numpy as np
import pytest

from cbp.collision import CollisionWorld, RobotGeometry
from cbp.state import RobotState
from cbp.testing import sample_configurations


@pytest.mark.parametrize("name", ["panda", "panda_planar", "panda_floating", "youbot"])
def test_compiled_placements_are_pinocchios(robots, rng, name) -> None:
    """Fixed, planar and floating bases: every shape's placement within 1e-12."""
    robot = robots[name]
    world = CollisionWorld(RobotGeometry(robot))
    assert world._kinematics is not None
    state = RobotState(robot)
    for q in sample_configurations(robot, rng, n=20):
        state.update(q)
        expected = world.shape_placements(state).homogeneous
        np.testing.assert_allclose(world.shape_frames(state), expected, atol=1e-12)
