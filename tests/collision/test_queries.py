"""Contact queries against known geometry: box, sphere, octree of the box, self."""

from __future__ import annotations

from dataclasses import replace

import coal
import numpy as np
import pinocchio as pin
import pybullet as pb
import pytest

from cbp.collision import (
    CollisionSettings,
    CollisionWorld,
    EnvironmentObject,
    MetaballRefiner,
    OccupancyEnvironment,
    PrimitiveEnvironment,
    RobotGeometry,
)
from cbp.collision.environment import signed_distance
from cbp.collision.geometry import PlacedShapes, ShapePlacements
from cbp.sim.scene import PybulletScene
from cbp.state import RobotState
from cbp.testing import sample_configurations


@pytest.fixture(scope="module")
def geometry(robots) -> RobotGeometry:
    return RobotGeometry(robots["panda"])


@pytest.mark.parametrize("gap", [0.03, -0.01])
def test_box_sphere_and_octree_agree_on_distance_and_normal(
    geometry, robots, gap
) -> None:
    """The hand's hull at home, ``gap`` above a box, a sphere and an octree of the box."""
    robot = robots["panda"]
    state = RobotState(robot, robot.home())
    hand = next(s for s in geometry.shapes if s.link == "panda_hand")
    M = hand.world_placement(state)
    world_vertices = np.asarray(hand.shape.points()).dot(M.rotation.T) + M.translation
    lowest = world_vertices[np.argmin(world_vertices[:, 2])]
    top = lowest[2] - gap
    box_centre = np.array([lowest[0], lowest[1], top - 0.1])
    box = EnvironmentObject.primitive(
        "box", "box", (0.3, 0.3, 0.2), pin.SE3(np.eye(3), box_centre)
    )
    R = 1.0
    sphere = EnvironmentObject.primitive(
        "ball", "sphere", (R,), pin.SE3(np.eye(3), lowest - [0, 0, gap + R])
    )
    # The box's top layer of cells at 1 cm, as a depth camera would see it.
    cell = 0.01
    xs = np.arange(-0.15 + cell / 2, 0.15, cell)
    X, Y = np.meshgrid(xs + lowest[0], xs + lowest[1])
    octree = OccupancyEnvironment(
        np.c_[X.ravel(), Y.ravel(), np.full(X.size, top - cell / 2)], cell
    )
    centres = np.array([state.data.oMf[hand.frame_id].act(hand.centre)])
    radii = np.array([hand.radius])
    # Tolerances: exact for shapes; against the cells, the hull's face planes give
    # 0.1 mm and 0.9 deg here (coal's octree contacts were off by 4.5 mm, 14 deg).
    for env, tol, max_deg in (
        (PrimitiveEnvironment([box]), 1e-6, 0.1),
        (PrimitiveEnvironment([sphere]), 1e-3, 3.0),
        (octree, 1e-3, 2.0),
    ):
        hits = env.query(_placed([hand], [M], centres, radii), 0.05, 3)
        k = int(np.argmin(hits.distance))
        d, n = hits.distance[k], hits.normal[k]
        assert d == pytest.approx(gap, abs=tol), type(env).__name__
        assert np.degrees(np.arccos(np.clip(n[2], -1, 1))) < max_deg, n
        # Witness points: robot side on the hand, at the stated signed distance.
        p, o = hits.point[k], hits.other_point[k]
        assert (p - o).dot(n) == pytest.approx(d, abs=tol)
        assert p[2] == pytest.approx(lowest[2], abs=tol + 1e-3)


def test_octree_contacts_are_reduced_per_link(geometry, robots) -> None:
    robot = robots["panda"]
    state = RobotState(robot, robot.home())
    p = state.frame_position(robot.frame_id("panda_hand"))
    cell = 0.01
    xs = np.arange(-0.2, 0.2, cell)
    X, Y = np.meshgrid(xs, xs)
    layer = np.c_[X.ravel() + p[0], Y.ravel() + p[1], np.full(X.size, p[2] - 0.08)]
    settings = CollisionSettings(
        activation_distance=0.05, self_collision=False, contacts_per_link=3
    )
    world = CollisionWorld(geometry, OccupancyEnvironment(layer, cell), settings)
    contacts = world.contacts(state)
    assert len(contacts) > 0
    assert np.bincount(contacts.shape).max() <= 3


def test_self_collision_found_when_folded_not_at_home(geometry, robots) -> None:
    robot = robots["panda"]
    world = CollisionWorld(
        geometry, settings=CollisionSettings(activation_distance=0.02)
    )
    home = world.check(robot.home())
    assert home.accepted
    assert home.penetration == 0.0
    # Shoulder forward, elbow fully bent, wrist folded: the hand meets the base.
    folded = robot.home()
    folded[1], folded[3], folded[4], folded[5] = 1.0, -3.05, -0.45, 3.2
    check = world.check(folded)
    assert not check.accepted
    selfs = check.contacts.select(check.contacts.is_self)
    assert selfs.penetration > 0.03
    pairs = {
        frozenset((geometry.shapes[i].link, geometry.shapes[j].link))
        for i, j, d in zip(selfs.shape, selfs.other_shape, selfs.distance, strict=True)
        if d < 0
    }
    assert frozenset(("panda_link0", "panda_hand")) in pairs
    # PyBullet, on the same convex hulls, agrees that the hand is in the base.
    with PybulletScene(robot, []) as scene:
        scene.set_configuration(folded)
        names = {
            pb.getJointInfo(scene.robot_id, j, physicsClientId=scene.client)[
                12
            ].decode(): j
            for j in range(
                pb.getNumJoints(scene.robot_id, physicsClientId=scene.client)
            )
        }
        points = pb.getClosestPoints(
            scene.robot_id,
            scene.robot_id,
            0.0,
            linkIndexA=-1,
            linkIndexB=names["panda_hand"],
            physicsClientId=scene.client,
        )
        assert points
        assert min(p[8] for p in points) < -0.01


@pytest.mark.parametrize("tree", [False, True], ids=["compiled", "k-d tree"])
def test_far_objects_change_nothing(geometry, robots, rng, monkeypatch, tree) -> None:
    """With many objects far away, contacts are those of the near ones.

    Both broad phases: the compiled one, and the k-d tree that takes over above
    ``TREE_MIN_OBJECTS`` (lowered here so that a hundred objects use it).
    """
    from cbp.collision import objects as module

    if tree:
        monkeypatch.setattr(module, "TREE_MIN_OBJECTS", 16)
    robot = robots["panda"]
    near = [
        EnvironmentObject.primitive(
            "table",
            "box",
            (0.8, 0.8, 0.05),
            pin.SE3(np.eye(3), np.array([0.5, 0, 0.3])),
        ),
        EnvironmentObject.primitive(
            "ball", "sphere", (0.1,), pin.SE3(np.eye(3), np.array([0.3, 0.3, 0.6]))
        ),
    ]
    far = [
        EnvironmentObject.primitive(
            f"far_{k}",
            "box",
            (0.2, 0.2, 0.2),
            pin.SE3(np.eye(3), np.array([4.0 + 0.5 * (k % 10), 0.5 * (k // 10), 0.1])),
        )
        for k in range(100)
    ]
    settings = CollisionSettings(activation_distance=0.1)
    few = CollisionWorld(geometry, PrimitiveEnvironment(near), settings)
    many = CollisionWorld(geometry, PrimitiveEnvironment(near + far), settings)
    found = 0
    for q in sample_configurations(robot, rng, n=40):
        a, b = few.check(q).contacts, many.check(q).contacts
        # The same contacts, maybe in another order.
        a = a.select(np.lexsort((a.distance, a.shape)))
        b = b.select(np.lexsort((b.distance, b.shape)))
        np.testing.assert_array_equal(a.shape, b.shape)
        np.testing.assert_allclose(a.distance, b.distance)
        found += len(a)
    assert found > 20


@pytest.mark.parametrize("gap", [0.03, -0.01])
def test_capsule_links_are_measured_exactly_against_cells(robots, gap) -> None:
    """With capsule links, cell contacts match coal's exact capsule-box distance."""
    robot = robots["panda"]
    capsules = RobotGeometry(robot, approximation="capsule")
    state = RobotState(robot, robot.home())
    hand = next(s for s in capsules.shapes if s.link == "panda_hand")
    M = hand.world_placement(state)
    cell = 0.01
    # A layer of cells whose top face lies ``gap`` below the capsule's lowest point.
    axis = M.rotation[:, 2] * hand.shape.halfLength
    ends = np.array([M.translation + axis, M.translation - axis])
    lowest = ends[np.argmin(ends[:, 2])] - [0.0, 0.0, hand.shape.radius]
    top = lowest[2] - gap
    xs = np.arange(-0.15 + cell / 2, 0.15, cell)
    X, Y = np.meshgrid(xs + lowest[0], xs + lowest[1])
    layer = OccupancyEnvironment(
        np.c_[X.ravel(), Y.ravel(), np.full(X.size, top - cell / 2)],
        cell,
        MetaballRefiner(),  # the direction to the nearest centre tilts by steps
    )
    box = EnvironmentObject.primitive(
        "box",
        "box",
        (0.3, 0.3, cell),
        pin.SE3(np.eye(3), np.array([lowest[0], lowest[1], top - cell / 2])),
    )
    centres = np.array([M.act(np.zeros(3))])
    radii = np.array([hand.radius])
    robot = _placed([hand], [M], centres, radii)
    exact = PrimitiveEnvironment([box]).query(robot, 0.05, 1)
    cells = layer.query(robot, 0.05, 3)
    k = int(np.argmin(cells.distance))
    assert cells.distance[k] == pytest.approx(exact.distance[0], abs=1e-3)
    assert cells.distance[k] == pytest.approx(gap, abs=1e-3)
    assert np.degrees(np.arccos(np.clip(cells.normal[k][2], -1, 1))) < 2.0
    # The robot witness lies on the capsule's surface.
    p = cells.point[k] - M.translation
    along = np.clip(
        p.dot(M.rotation[:, 2]), -hand.shape.halfLength, hand.shape.halfLength
    )
    radial = np.linalg.norm(p - along * M.rotation[:, 2])
    assert radial == pytest.approx(hand.shape.radius, abs=1e-9)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_non_finite_configuration_is_never_accepted(geometry, robots, bad) -> None:
    """Step validation rejects NaN or infinite joints instead of finding no contact."""
    robot = robots["panda"]
    cells = np.stack(np.meshgrid(*[np.arange(10) * 0.01] * 2), -1).reshape(-1, 2)
    octree = OccupancyEnvironment(np.c_[cells + 0.3, np.full(len(cells), 0.2)], 0.01)
    for env in (octree, PrimitiveEnvironment([])):
        world = CollisionWorld(geometry, env)
        q = robot.home()
        q[3] = bad
        check = world.check(q)
        assert not check.accepted
        assert check.penetration == np.inf
        assert world.check(robot.home()).accepted


def _shapes_at(world: CollisionWorld, q: np.ndarray) -> PlacedShapes:
    """The world's shapes at q, with their bounding centres and boxes."""
    return world.placed(RobotState(world.geometry.robot, q))


def _spheres_only(robot: PlacedShapes) -> PlacedShapes:
    """The same shapes with boxes that bound nothing: the spheres' broad phase."""
    return replace(robot, halves=np.full_like(robot.centres, np.inf))


def _placed(shapes, placements, centres, radii) -> PlacedShapes:
    """Shapes placed by hand, with the spheres' broad phase only."""
    return PlacedShapes(
        list(shapes),
        ShapePlacements(placements),
        np.asarray(centres, dtype=float),
        np.asarray(radii, dtype=float),
        np.full((len(shapes), 3), np.inf),
    )


def test_box_broad_phase_loses_no_contact(geometry, robots, rng) -> None:
    """Spheres and boxes select the same contacts as spheres alone, with fewer pairs.

    Thin boards beside the arm: every pair within the margin must reach coal;
    the boxes only drop pairs that are farther.
    """
    robot = robots["panda"]
    boards = [
        EnvironmentObject.primitive(
            f"board_{k}",
            "box",
            (0.02, 0.6, 0.3),
            pin.SE3(np.eye(3), np.array([0.3 + 0.15 * k, 0.0, 0.4])),
        )
        for k in range(4)
    ]
    env = PrimitiveEnvironment(boards)
    world = CollisionWorld(geometry, env, CollisionSettings(activation_distance=0.08))
    margin = world.margin(env)
    found = dropped = 0
    for q in sample_configurations(robot, rng, n=60):
        robot = _shapes_at(world, q)
        placements, centres, halves = robot.placements, robot.centres, robot.halves
        spheres = env.query(_spheres_only(robot), margin, 99)
        boxes = env.query(robot, margin, 99)
        np.testing.assert_array_equal(spheres.shape, boxes.shape)
        np.testing.assert_allclose(spheres.distance, boxes.distance)
        own_margin = world.settings.activation_distance + 2 * world.padding
        near_spheres = geometry.near_self_pairs(centres, own_margin)
        near_boxes = geometry.near_self_pairs(centres, own_margin, halves)
        assert set(near_boxes) <= set(near_spheres)
        for k in set(near_spheres) - set(near_boxes):  # dropped: truly farther
            i, j = geometry.self_pairs[k]
            d = signed_distance(
                geometry.shapes[j].shape,
                placements[j],
                geometry.shapes[i].shape,
                placements[i],
                coal.DistanceRequest(),
                coal.DistanceResult(),
            )[0]
            assert d >= own_margin
            dropped += 1
        found += len(boxes)
    assert found > 30
    assert dropped > 10


def test_broad_phase_keeps_every_pair_within_the_margin(geometry, robots, rng) -> None:
    """No (shape, object) pair that coal puts within the margin is culled.

    Boxes of random sizes and orientations, near the robot and scattered around.
    """
    robot = robots["panda"]
    objects = [
        EnvironmentObject.primitive(
            f"box_{k}",
            "box",
            tuple(rng.uniform(0.02, 0.3, 3)),
            pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)), centre),
        )
        for k, centre in enumerate(
            rng.uniform([-1.0, -1.0, -0.2], [1.0, 1.0, 1.3], (40, 3))
        )
    ]
    env = PrimitiveEnvironment(objects)
    world = CollisionWorld(geometry, env, CollisionSettings(activation_distance=0.08))
    margin = world.margin(env)
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    found = 0
    for q in sample_configurations(robot, rng, n=30):
        robot = _shapes_at(world, q)
        placements = robot.placements
        hits = env.query(robot, margin, 99)
        expected = sorted(
            (s, d)
            for s, shape in enumerate(geometry.shapes)
            for obj in objects
            if (
                d := signed_distance(
                    obj.shape,
                    obj.placement,
                    shape.shape,
                    placements[s],
                    request,
                    result,
                )[0]
            )
            < margin
        )
        got = sorted(zip(hits.shape.tolist(), hits.distance.tolist(), strict=True))
        assert [s for s, _ in got] == [s for s, _ in expected]
        # Coal's GJK stops within its default tolerance (1e-6, relative).
        np.testing.assert_allclose(
            [d for _, d in got], [d for _, d in expected], rtol=0, atol=1e-6
        )
        found += len(got)
    assert found > 30


def test_a_snapshot_published_while_a_plan_is_made_waits_for_it(geometry) -> None:
    """Within ``holding`` the obstacles stay; the newest published is taken after."""
    world = CollisionWorld(geometry, PrimitiveEnvironment([]))
    first = world.environment
    second, third = PrimitiveEnvironment([]), PrimitiveEnvironment([])
    with world.holding() as held:
        assert held is first
        with world.holding():  # nested: the outermost hold decides
            world.set_environment(second)
            world.set_environment(third)
        assert world.environment is first
    assert world.environment is third
    world.set_environment(second)  # no plan in progress: at once
    assert world.environment is second


def test_a_contact_not_measured_counts_as_the_deepest() -> None:
    """A NaN distance makes the penetration infinite: the step it validates is refused."""
    from cbp.collision import ContactSet

    def contacts(distance: list[float]) -> ContactSet:
        n = len(distance)
        return ContactSet(
            np.zeros(n, dtype=np.int64),
            np.full(n, -1, dtype=np.int64),
            np.zeros((n, 3)),
            np.zeros((n, 3)),
            np.tile([0.0, 0.0, 1.0], (n, 1)),
            np.array(distance, dtype=float),
        )

    assert contacts([]).penetration == 0.0
    assert contacts([0.01, 0.02]).penetration == 0.0
    assert contacts([0.01, -0.003]).penetration == pytest.approx(0.003)
    assert contacts([0.01, float("nan"), -0.003]).penetration == float("inf")


def test_a_contact_measured_ahead_keeps_its_lead_through_the_set_operations() -> None:
    """``lead`` follows each contact through concatenation, selection and stacking.

    ``penetration`` is what the contact rows see (the obstacle where it may
    come), ``present_penetration`` what step validation sees (where it is).
    """
    from cbp.collision import ContactSet

    n = 3
    ahead = ContactSet.obstacles(
        np.arange(n),
        np.zeros((n, 3)),
        np.zeros((n, 3)),
        np.tile([0.0, 0.0, 1.0], (n, 1)),
        np.array([-0.05, 0.02, -0.01]),
    )
    ahead.lead = np.array([0.08, 0.08, 0.0])
    still = ContactSet.obstacles(
        np.array([4]),
        np.zeros((1, 3)),
        np.zeros((1, 3)),
        np.array([[1.0, 0.0, 0.0]]),
        np.array([-0.002]),
    )
    both = ContactSet.concatenate([still, ahead])
    assert both.lead is not None
    np.testing.assert_array_equal(both.lead, [0.0, 0.08, 0.08, 0.0])
    assert both.penetration == pytest.approx(0.05)
    assert both.present_penetration == pytest.approx(0.01)  # the third, no lead
    chosen = both.select(np.array([1, 3]))
    assert chosen.lead is not None
    np.testing.assert_array_equal(chosen.lead, [0.08, 0.0])
    own = ContactSet.obstacles(
        np.array([0]), np.zeros((1, 3)), np.zeros((1, 3)), np.eye(3)[:1], np.ones(1)
    )
    own.other_shape = np.array([2])
    stacked = ContactSet.stack(ahead, 0.01, own)
    assert stacked.lead is not None
    np.testing.assert_array_equal(stacked.lead, [0.08, 0.08, 0.0, 0.0])
    assert stacked.present_penetration == pytest.approx(0.02)
    environment = stacked.environment_part()
    assert environment.lead is not None
    assert len(environment.lead) == n
    assert still.present_penetration == still.penetration  # nothing ahead
