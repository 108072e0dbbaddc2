"""Yes-or-no checks (FreeSpaceChecker) give the contact query's answer."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from cbp.collision import (
    CollisionSettings,
    CollisionWorld,
    EnvironmentObject,
    OccupancyEnvironment,
    PrimitiveEnvironment,
    RobotGeometry,
)
from cbp.collision.checker import FreeSpaceChecker
from cbp.collision.convex_kernels import self_overlap
from cbp.state import RobotState
from cbp.testing import sample_configurations


@pytest.fixture(scope="module")
def geometry(robots) -> RobotGeometry:
    return RobotGeometry(robots["panda"], padding=0.01)


def _shelf() -> list[EnvironmentObject]:
    boards = [
        ("floor", (0.6, 0.8, 0.02), (0.6, 0.0, 0.2)),
        ("middle", (0.6, 0.8, 0.02), (0.6, 0.0, 0.5)),
        ("top", (0.6, 0.8, 0.02), (0.6, 0.0, 0.8)),
        ("side", (0.6, 0.02, 0.6), (0.6, 0.4, 0.5)),
        ("ball", (0.12,), (0.3, -0.4, 0.6)),
    ]
    return [
        EnvironmentObject.primitive(
            name,
            "sphere" if len(size) == 1 else "box",
            size,
            pin.SE3(np.eye(3), np.array(c, dtype=float)),
        )
        for name, size, c in boards
    ]


def test_agrees_with_the_contact_query_on_declared_objects(
    geometry, robots, rng
) -> None:
    """Free exactly when check() finds no penetration of the padded shapes."""
    world = CollisionWorld(geometry, PrimitiveEnvironment(_shelf()))
    qs = sample_configurations(robots["panda"], rng, n=400)
    expected = np.array([world.check(q).penetration == 0.0 for q in qs])
    got = np.array([world.is_free(q) for q in qs])
    assert 50 < expected.sum() < 350  # both answers are well represented
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("tolerance", [0.002, 0.008])
def test_agrees_with_the_contact_query_on_an_octree(
    geometry, robots, rng, tolerance
) -> None:
    """Against an occupancy map, by CAT's rule, to sub-millimetre.

    Free when no padded shape reaches deeper than ``penetration_tolerance``
    plus half a cell into the map's inflated cells (what CAT's step
    validation accepts) and no two padded shapes of a checked pair overlap;
    also with a tolerance above half a cell (coal refuses a negative margin
    against an octree). The cells lie on the map's grid, as a map's do. The
    query measures a cell's inscribed sphere, the check the cube: where an
    edge or corner is nearest, the check may be stricter by up to 0.37 cell.
    """
    cell = 0.02
    xs = np.arange(0.3 + cell / 2, 0.9, cell)
    ys = np.arange(-0.4 + cell / 2, 0.4, cell)
    X, Y = np.meshgrid(xs, ys)
    layer = np.c_[X.ravel(), Y.ravel(), np.full(X.size, 0.5 + cell / 2)]
    settings = CollisionSettings(penetration_tolerance=tolerance)
    world = CollisionWorld(geometry, OccupancyEnvironment(layer, cell), settings)
    qs = sample_configurations(robots["panda"], rng, n=300)
    checks = [world.check(q) for q in qs]
    got = np.array([world.is_free(q) for q in qs])
    limit = tolerance + 0.5 * cell

    def depths(check):  # (into the map, between the robot's own shapes)
        own = check.contacts.other_shape >= 0
        d = check.contacts.distance
        return max(0.0, -d[~own].min(initial=0.0)), max(0.0, -d[own].min(initial=0.0))

    into, between = np.array([depths(c) for c in checks]).T
    expected = (into <= limit) & (between == 0.0)
    assert 30 < expected.sum() < 270
    # Reaching into the map beyond the tolerance alone: CAT accepts it.
    assert (got & (into > tolerance)).any()
    corner = 0.5 * (np.sqrt(3.0) - 1.0) * cell
    for k in np.flatnonzero(got != expected):
        if between[k] > 0.0:
            assert between[k] < 1e-3, between[k]
        elif got[k]:
            assert into[k] - limit < 1e-3, into[k]
        else:
            assert into[k] > limit - corner, into[k]


@pytest.mark.parametrize(("gap", "free"), [(0.015, True), (0.005, False)])
def test_padding_counts_even_when_bounding_boxes_do_not_overlap(
    geometry, robots, gap, free
) -> None:
    """A box ``gap`` below the hand's lowest point: inside the 1 cm padding it collides."""
    robot = robots["panda"]
    state = RobotState(robot, robot.home())
    points = np.concatenate(
        [
            np.asarray(s.shape.points()).dot(M.rotation.T) + M.translation
            for s in geometry.shapes
            if s.link.startswith(
                ("panda_hand", "panda_leftfinger", "panda_rightfinger")
            )
            for M in [s.world_placement(state)]
        ]
    )
    lowest = points[np.argmin(points[:, 2])]
    box = EnvironmentObject.primitive(
        "box",
        "box",
        (0.05, 0.05, 0.05),
        pin.SE3(np.eye(3), lowest - [0.0, 0.0, gap + 0.025]),
    )
    world = CollisionWorld(
        geometry, PrimitiveEnvironment([box]), CollisionSettings(self_collision=False)
    )
    assert world.is_free(robot.home()) is free
    assert (world.check(robot.home()).penetration == 0.0) is free


def test_new_environment_snapshots_are_used(geometry, robots) -> None:
    """After set_environment the next check sees the new obstacles."""
    robot = robots["panda"]
    world = CollisionWorld(geometry)
    q = robot.home()
    assert world.is_free(q)
    hand = RobotState(robot, q).frame_position(robot.frame_id("panda_hand"))
    ball = EnvironmentObject.primitive(
        "ball", "sphere", (0.05,), pin.SE3(np.eye(3), hand)
    )
    world.set_environment(PrimitiveEnvironment([ball]))
    assert not world.is_free(q)


def test_the_compiled_self_check_agrees_with_coals(geometry, robots, rng) -> None:
    """The planners' self check against a map answers as coal's for the robot's pairs."""
    world = CollisionWorld(geometry, PrimitiveEnvironment([]))
    coal_check = FreeSpaceChecker(geometry, PrimitiveEnvironment([]), geometry.padding)
    table = world._table
    pad2 = 2.0 * geometry.padding
    pairs = (table.first, table.second, np.zeros((len(table.first), 5)), pad2, pad2)
    state = RobotState(robots["panda"])
    got, expected = [], []
    for q in sample_configurations(robots["panda"], rng, n=600):
        state.update(q)
        got.append(self_overlap(world.shape_frames(state), table.bounds, pairs))
        expected.append(0 if coal_check.is_free(q) else 1)
    assert 30 < sum(expected) < 570  # both answers are well represented
    np.testing.assert_array_equal(got, expected)
