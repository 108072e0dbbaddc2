"""Leaving the padding: a planner's start where CAT rests against an obstacle.

CAT's contact rows hold the padded shapes at an obstacle's surface, a rounding
error inside it; a planner that needs a start free of contact (the hybrid's
RRT-Connect) must first move them out (:func:`clear_padding`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

from cbp.collision import (
    CollisionSettings,
    CollisionWorld,
    EnvironmentObject,
    PrimitiveEnvironment,
    RobotGeometry,
)
from cbp.run.backout import CLEAR, back_out, clear_padding
from cbp.scenario import load_scenario
from cbp.state import RobotState

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
PADDING = 0.01


def _world_with_box_under_hand(depth: float) -> tuple[CollisionWorld, np.ndarray]:
    """A padded world whose box reaches ``depth`` [m] into the padded arm at q0."""
    scenario = load_scenario(SCENARIOS / "cat_pushed_obstacle.yaml")
    robot = scenario.robot
    state = RobotState(robot, scenario.q0)
    hand = state.data.oMf[robot.frame_id("panda_hand")].translation
    world = CollisionWorld(
        RobotGeometry(robot, padding=PADDING),
        PrimitiveEnvironment([]),
        CollisionSettings(activation_distance=0.2, padding=PADDING),
    )

    def place(top: float) -> float:
        slab = EnvironmentObject.primitive(
            "box",
            "box",
            (0.2, 0.2, 0.1),
            pin.SE3(np.eye(3), np.array([hand[0], hand[1] + 0.02, top - 0.05])),
        )
        world.set_environment(PrimitiveEnvironment([slab]))
        obstacles = world.query(state).environment_part()
        return float(obstacles.distance.min()) if len(obstacles) else 1.0

    low, high = hand[2] - 0.5, hand[2]  # place(low) > 0 > place(high)
    for _ in range(60):
        mid = 0.5 * (low + high)
        if place(mid) > -depth:
            low = mid
        else:
            high = mid
    place(0.5 * (low + high))
    return world, scenario.q0.copy()


def test_a_rest_within_the_padding_is_left_along_the_normals() -> None:
    """0.1 mm into the padding: out to a free start in small steps, never nearer."""
    world, q = _world_with_box_under_hand(1e-4)
    assert not world.is_free(q)
    step = np.full(q.size, 0.01)
    # The unpadded arm is a padding away: nothing to back out of.
    assert back_out(world, q, step)[0] is None
    path = clear_padding(world, q, step)
    assert path is not None
    np.testing.assert_array_equal(path[0], q)
    assert world.is_free(path[-1])
    assert np.all(np.abs(np.diff(path, axis=0)) <= step + 1e-12)
    state = RobotState(world.geometry.robot)
    nearest = []
    for point in path:
        state.update(point)
        nearest.append(float(world.query(state).environment_part().distance.min()))
    assert nearest[-1] >= CLEAR - 1e-4
    assert min(nearest) >= nearest[0] - 1e-6


def test_a_start_clear_of_the_padding_needs_no_path() -> None:
    """Already free: None, as when no way out is found."""
    world, q = _world_with_box_under_hand(-0.005)
    assert world.is_free(q)
    assert clear_padding(world, q, np.full(q.size, 0.01)) is None


def test_a_start_deep_in_an_obstacle_is_not_called_clear() -> None:
    """5 cm in: not out within the path's points at 1 mrad a point, so None."""
    world, q = _world_with_box_under_hand(0.05)
    assert clear_padding(world, q, np.full(q.size, 0.001)) is None
