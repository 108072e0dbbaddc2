"""Approach speeds from successive map snapshots, and snapshots measured ahead."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from cbp.collision import CollisionWorld, OccupancyEnvironment, RobotGeometry
from cbp.perception.motion import ApproachEstimator
from cbp.state import RobotState

CELL = 0.01


@pytest.fixture(scope="module")
def setup(robots):
    robot = robots["panda"]
    world = CollisionWorld(RobotGeometry(robot))
    state = RobotState(robot, robot.home())
    hand = world.geometry.shapes.index(
        next(s for s in world.geometry.shapes if s.link == "panda_hand")
    )
    return world, state, hand


def _wall(state: RobotState, gap: float) -> OccupancyEnvironment:
    """A 20 x 20 cm wall of cells ``gap`` [m] below the hand's frame origin."""
    hand = state.data.oMf[state.robot.frame_id("panda_hand")].translation
    below = np.floor((hand[2] - gap) / CELL) * CELL + 0.5 * CELL
    ij = (np.arange(-10, 10) + 0.5) * CELL
    x, y = np.meshgrid(np.round(hand[0] / CELL) * CELL + ij, hand[1] + ij)
    cells = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, below)])
    return OccupancyEnvironment(cells, CELL)


def test_a_wall_coming_at_the_hand_is_measured_at_its_speed(setup) -> None:
    """One cell every 0.2 s (5 cm/s): about that for the hand, 0 for the base."""
    world, state, hand = setup
    estimator = ApproachEstimator(world, window=1.0)
    old = None
    speeds = np.zeros(0)
    for k in range(16):  # a snapshot every 0.1 s
        new = _wall(state, 0.20 - 0.01 * (k // 2))
        speeds = estimator.update(0.1 * k, state, old, new)
        old = new
    fingers = speeds[hand:]  # the hand and its fingers (the nearest)
    assert 0.03 < fingers.max() < 0.07, speeds
    assert speeds[0] == 0.0  # the base: nothing within its margin


def test_a_map_that_only_changes_identity_or_flickers_gives_no_speed(setup) -> None:
    world, state, _ = setup
    estimator = ApproachEstimator(world, window=1.0)
    old = _wall(state, 0.15)
    for k in range(1, 30):
        # Rebuilt every frame; one frame in five a cell nearer (a flicker).
        new = _wall(state, 0.14 if k % 5 == 0 else 0.15)
        speeds = estimator.update(k / 30.0, state, old, new)
        assert not speeds.any(), (k, speeds)
        old = new


def test_a_snapshot_ahead_reports_each_shape_nearer(setup) -> None:
    world, state, hand = setup
    env = _wall(state, 0.08)
    robot = world.placed(state)
    nearer = np.zeros(len(world.geometry.shapes))
    nearer[hand] = 0.02
    ahead = env.ahead(nearer)
    assert ahead is not env
    assert ahead.index is env.index  # the same cells, not copied
    margin = world.margin(env)
    now, then = env.query(robot, margin, 3), ahead.query(robot, margin, 3)
    np.testing.assert_array_equal(then.shape, now.shape)
    np.testing.assert_allclose(then.distance, now.distance - nearer[now.shape])
    assert (now.shape == hand).any()
    assert env.ahead(None).nearer is None


def test_placed_apart_matches_placed(setup) -> None:
    world, state, _ = setup
    a, b = world.placed(state), world.placed_apart(state)
    for M, N in zip(a.placements, b.placements, strict=True):
        assert M.isApprox(N, 1e-12)
    np.testing.assert_allclose(a.centres, b.centres)
    np.testing.assert_allclose(a.halves, b.halves)
    assert isinstance(a.placements[0], pin.SE3)


def _grid_cells(lower: np.ndarray, shape: tuple[int, int, int], boxes) -> np.ndarray:
    """A grid of cell states: FREE, with OCCUPIED boxes (lo, hi) in metres."""
    from cbp.perception.kernels import FREE, OCCUPIED

    cells = np.full(shape, FREE, dtype=np.uint8)
    for lo, hi in boxes:
        a = np.floor((np.asarray(lo) - lower) / CELL).astype(int)
        b = np.floor((np.asarray(hi) - lower) / CELL).astype(int)
        cells[a[0] : b[0], a[1] : b[1], a[2] : b[2]] = OCCUPIED
    return cells


def test_a_moving_box_beside_a_nearer_static_one_is_measured_on_its_own(
    setup,
) -> None:
    """10 cm/s toward the hand; a still slab nearer: the box's velocity, not 0.

    The per-shape approach estimate sees the hand's nearest obstacle, the
    still slab, and gives 0; the clusters give the box its velocity, and the
    snapshot swept over the look-ahead holds the cells it will reach.
    """
    from cbp.collision.map_environment import BlockedGrid
    from cbp.perception.kernels import OCCUPIED
    from cbp.perception.motion import ClusterMotion, swept_snapshot

    world, state, hand = setup
    h = state.data.oMf[state.robot.frame_id("panda_hand")].translation
    lower = np.floor(h / CELL) * CELL - 0.5
    shape = (100, 100, 100)
    slab = (
        h + np.array([-0.1, -0.1, -0.09]),
        h + np.array([0.1, 0.1, -0.07]),
    )  # under the fingers
    clusters = ClusterMotion(lower, CELL, window=0.5)
    estimator = ApproachEstimator(world, window=0.5)
    shapes = world.geometry.world_shapes(state)
    old = None
    for k in range(8):  # a snapshot every 0.1 s, the box a cell nearer each
        x = 0.25 - 0.01 * k
        box = (h + np.array([x, -0.05, -0.05]), h + np.array([x + 0.1, 0.05, 0.05]))
        cells = _grid_cells(lower, shape, [slab, box])
        mask = cells == OCCUPIED
        centres = lower + (np.argwhere(mask) + 0.5) * CELL
        env = OccupancyEnvironment(
            centres, CELL, blocked=BlockedGrid(mask, lower, CELL)
        )
        moving = clusters.update(0.1 * k, cells, shapes)
        speeds = estimator.update(0.1 * k, state, old, env)
        old = env
    assert speeds[hand:].max() == 0.0  # hidden behind the still slab
    assert len(moving) == 1
    np.testing.assert_allclose(moving[0].velocity, [-0.1, 0.0, 0.0], atol=0.015)
    swept = swept_snapshot(env, moving, 0.4, lower)
    ahead = (h + np.array([x - 0.035, 0.0, 0.0]))[None]  # 3.5 cm in front of the box
    assert not env.inside(ahead)[0]
    assert swept.inside(ahead)[0]
    assert len(swept) > len(env)
    assert swept_snapshot(env, [], 0.4, lower) is env


def test_clusters_that_stand_still_do_not_move(setup) -> None:
    """The same cells every snapshot, and a cell flickering: nothing moves."""
    from cbp.perception.motion import ClusterMotion

    world, state, _ = setup
    h = state.data.oMf[state.robot.frame_id("panda_hand")].translation
    lower = np.floor(h / CELL) * CELL - 0.5
    clusters = ClusterMotion(lower, CELL, window=0.5)
    shapes = world.geometry.world_shapes(state)
    box = (h + np.array([0.1, -0.05, -0.05]), h + np.array([0.2, 0.05, 0.05]))
    for k in range(10):
        flicker = (h + np.array([0.09, 0.0, 0.0]), h + np.array([0.1, 0.01, 0.01]))
        boxes = [box, flicker] if k % 3 == 0 else [box]
        moving = clusters.update(0.1 * k, _grid_cells(lower, (100,) * 3, boxes), shapes)
        assert moving == [], k
