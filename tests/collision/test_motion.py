"""The sweep bound: how far the robot's shapes move between checked configurations."""

from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin
import pytest

from cbp.collision import (
    CollisionWorld,
    EnvironmentObject,
    PrimitiveEnvironment,
    RobotGeometry,
)
from cbp.collision.motion import SweepBound
from cbp.testing import sample_configurations


@pytest.fixture(scope="module")
def geometry(robots) -> RobotGeometry:
    return RobotGeometry(robots["panda"], padding=0.01)


def _points_on_shapes(geometry: RobotGeometry, rng) -> list[tuple[int, np.ndarray]]:
    """(frame, points (k, 3) in the frame) per shape.

    Its centre and 20 points on its bounding sphere, the farthest any point of
    the shape can be.
    """
    out = []
    for shape in geometry.shapes:
        directions = rng.normal(size=(20, 3))
        directions /= np.linalg.norm(directions, axis=1)[:, None]
        local = np.vstack([shape.centre, shape.centre + shape.radius * directions])
        out.append((shape.frame_id, local))
    return out


def test_no_point_of_a_shape_moves_farther_than_the_bound(geometry, robots, rng):
    """Along random segments, every point's path length stays within the bound."""
    robot = robots["panda"]
    bound = SweepBound(geometry)
    points = _points_on_shapes(geometry, rng)
    data = robot.model.createData()
    starts = sample_configurations(robot, rng, n=30)
    ratios = []
    for a in starts:
        b = np.clip(
            a + rng.uniform(-0.4, 0.4, size=a.size),
            robot.lower_limits,
            robot.upper_limits,
        )
        travelled = np.zeros(sum(len(p) for _, p in points))
        previous = None
        for f in np.linspace(0.0, 1.0, 201):
            pin.framesForwardKinematics(robot.model, data, a + f * (b - a))
            placed = np.vstack(
                [
                    p @ data.oMf[i].rotation.T + data.oMf[i].translation
                    for i, p in points
                ]
            )
            if previous is not None:
                travelled += np.linalg.norm(placed - previous, axis=1)
            previous = placed
        limit = bound.distance(a, b)
        assert travelled.max() <= limit + 1e-9
        ratios.append(travelled.max() / limit)
    # A bound, not a wild one: the farthest point moves a good part of it.
    assert np.median(ratios) > 0.3


def test_configurations_between_are_a_step_apart_by_the_bound(geometry, robots, rng):
    bound = SweepBound(geometry)
    robot = robots["panda"]
    qs = sample_configurations(robot, rng, n=20)
    for a, b in itertools.pairwise(qs):
        between = bound.between(a, b, 0.01)
        chain = np.vstack([a, between, b])
        steps = [bound.distance(p, q) for p, q in itertools.pairwise(chain)]
        assert max(steps) <= 0.01 + 1e-12
        assert len(between) == int(np.ceil(bound.distance(a, b) / 0.01)) - 1
    assert len(bound.between(qs[0], qs[0], 0.01)) == 0
    # The last joints carry only the hand: a small reach; the first, the arm.
    assert bound.reach[-1] < 0.3 < 0.9 < bound.reach[0] < 1.3


def test_a_base_that_is_not_a_scalar_joint_is_refused(robots) -> None:
    with pytest.raises(ValueError, match="JointModelPlanar"):
        SweepBound(RobotGeometry(robots["youbot"]))


def plate_across_the_hand(robot, a: np.ndarray, b: np.ndarray) -> EnvironmentObject:
    """A 3 mm plate across the hand's way, halfway from ``a`` to ``b``."""
    data = robot.model.createData()
    hand = robot.frame_id("panda_hand")
    ends = []
    for q in (a, 0.5 * (a + b), b):
        pin.framesForwardKinematics(robot.model, data, q)
        ends.append(data.oMf[hand].translation.copy())
    along = ends[2] - ends[0]
    x = along / np.linalg.norm(along)
    z = np.array([0.0, 0.0, 1.0])
    y = np.cross(z, x)
    rotation = np.column_stack([x, y, np.cross(x, y)])
    return EnvironmentObject.primitive(
        "plate", "box", (0.003, 0.08, 0.12), pin.SE3(rotation, ends[1])
    )


def test_a_thin_plate_between_two_free_configurations_is_found(geometry, robots):
    """Both ends are free; the motion between them is not."""
    robot = robots["panda"]
    a = robot.home()
    b = a.copy()
    b[0] += 1.2  # the shoulder turns: the hand sweeps about 35 cm
    world = CollisionWorld(
        geometry, PrimitiveEnvironment([plate_across_the_hand(robot, a, b)])
    )
    assert world.is_free(a)
    assert world.is_free(b)
    assert not world.motion_free(a, b)
    assert world.motion_free(a, a + 0.1 * (b - a))  # short of the plate
