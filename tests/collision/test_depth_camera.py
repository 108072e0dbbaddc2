"""Depth camera to occupancy map in PyBullet: surfaces found, robot filtered, clearing."""

from __future__ import annotations

import numpy as np
import pytest

from cbp.collision import (
    CollisionSettings,
    CollisionWorld,
    EnvironmentObject,
    PrimitiveEnvironment,
    RobotGeometry,
)
from cbp.perception.kernels import OCCUPIED
from cbp.perception.mapper import MapUpdater
from cbp.perception.motion import ApproachEstimator
from cbp.perception.occupancy import OccupancyGrid
from cbp.perception.spec import CameraSpec, DepthNoise, PerceptionSpec
from cbp.scenario import ObjectSpec
from cbp.sim.camera import DepthCamera
from cbp.sim.scene import PybulletScene
from cbp.spatial import Pose
from cbp.state import RobotState

TABLE = ObjectSpec(
    name="table",
    shape="box",
    size=(0.6, 1.0, 0.04),
    pose=Pose(position=(0.6, 0.0, 0.18)),
)
BOX = ObjectSpec(
    name="box",
    shape="box",
    size=(0.12, 0.12, 0.12),
    pose=Pose(position=(0.55, 0.2, 0.26), rpy_deg=(0.0, 0.0, 30.0)),
)
#: Frames exactly as rendered: these tests check the map's geometry (the noise
#: model has its own, tests/sim/test_depth_noise.py).
EXACT = DepthNoise(enabled=False)
CAMERA = CameraSpec(
    position=(1.5, 0.0, 1.0), target=(0.5, 0.0, 0.2), far=3.0, noise=EXACT
)
SPEC = PerceptionSpec(
    source="depth_camera",
    camera=CAMERA,
    cell_size=0.01,
    bounds=((-0.3, -0.6, 0.0), (1.0, 0.6, 1.2)),
    misses_to_clear=2,
)


@pytest.fixture
def scene(robots):
    robot = robots["panda"]
    with PybulletScene(robot, [TABLE, BOX]) as scene:
        scene.set_configuration(robot.home())
        yield scene


def _objects(specs):
    return PrimitiveEnvironment(
        [
            EnvironmentObject.primitive(o.name, o.shape, o.size, o.pose.to_se3())
            for o in specs
        ]
    )


def test_cells_lie_on_the_box_and_table_and_none_on_the_robot(scene, robots) -> None:
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    grid = OccupancyGrid(SPEC, geometry)
    state = RobotState(robot, robot.home())
    grid.integrate(DepthCamera(scene.client, CAMERA).capture(), state)
    centres = grid.centres()
    assert len(centres) > 2000
    # Every cell is within a cell diagonal of a true surface ...
    clearance = _objects([TABLE, BOX]).clearance(centres)
    near = np.mean(clearance <= np.sqrt(3) * grid.cell)
    assert near > 0.98, near
    # ... the box's visible faces are covered ...
    on_box = _objects([BOX]).clearance(centres) <= grid.cell
    assert on_box.sum() > 150
    # ... and no cell lies inside the robot (the camera sees most of the arm).
    assert grid.robot_points_removed > 1000
    inside_robot = geometry.contains(state, centres, margin=-geometry.padding)
    assert not inside_robot.any()


def test_a_failing_approach_estimate_still_publishes_the_map(scene, robots) -> None:
    """The estimate is an addition: when it fails the map goes out without it."""

    class Failing(ApproachEstimator):
        def update(self, *args):  # type: ignore[no-untyped-def]
            raise FloatingPointError("injected")

    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    world = CollisionWorld(geometry)
    grid = OccupancyGrid(SPEC, geometry)
    mapper = MapUpdater(grid, world, estimator=Failing(world, 1.0))
    try:
        mapper.submit(DepthCamera(scene.client, CAMERA).capture(), robot.home(), 0.1)
        assert mapper.wait_idle()
    finally:
        mapper.close()
    assert world.environment is grid.environment()  # published, as mapped
    assert "approach estimate failed" in str(mapper.error)
    assert "injected" in str(mapper.error)


def test_a_removed_box_clears_within_the_stated_frames(scene, robots) -> None:
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    grid = OccupancyGrid(SPEC, geometry)
    world = CollisionWorld(geometry)
    mapper = MapUpdater(grid, world)  # threaded, as in a run
    camera = DepthCamera(scene.client, CAMERA)
    q = robot.home()
    try:
        for _ in range(2):
            mapper.submit(camera.capture(), q)
            assert mapper.wait_idle()
        box_env, table_env = _objects([BOX]), _objects([TABLE])

        def box_cells() -> int:
            # On the box, and not the table top that the box was standing on.
            centres = grid.centres()
            on_box = box_env.clearance(centres) <= grid.cell
            return int(np.sum(on_box & (table_env.clearance(centres) > grid.cell)))

        assert box_cells() > 150
        scene.remove_object("box")
        remaining = []
        for _ in range(SPEC.misses_to_clear):
            mapper.submit(camera.capture(), q)
            assert mapper.wait_idle()
            remaining.append(box_cells())
        assert mapper.error is None
        assert remaining[0] > 0, remaining  # one miss is not enough ...
        assert remaining[-1] == 0, remaining  # ... two are
        assert world.environment_version == mapper.updates == 2 + SPEC.misses_to_clear
    finally:
        mapper.close()


def test_an_obstacle_inside_the_padding_is_mapped_and_the_arm_is_not(robots) -> None:
    """The self-filter drops readings within robot_margin of the arm's shapes only.

    A wall stands 7 mm beside the hand: inside the 1 cm padding, beyond the 5 mm
    margin. Before it was measured from the shapes the filter dropped every
    reading within the padding plus 2 cm, so the wall's face beside the hand was
    never mapped (an obstacle pushed into the arm vanished before it touched).
    """
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    state = RobotState(robot, robot.home())
    hand = state.data.oMf[robot.frame_id("panda_hand")].translation
    unpadded = CollisionWorld(
        RobotGeometry(robot, padding=0.0),
        settings=CollisionSettings(
            activation_distance=1.0, self_collision=False, padding=0.0
        ),
    )

    def wall_at(y: float) -> ObjectSpec:
        return ObjectSpec(
            name="wall",
            shape="box",
            size=(0.3, 0.02, 0.3),
            pose=Pose(position=(float(hand[0]), y, float(hand[2]))),
        )

    def clearance(y: float) -> float:  # from the unpadded arm to the wall at y
        unpadded.set_environment(_objects([wall_at(y)]))
        return float(unpadded.check(state.q).contacts.distance.min())

    gap = 0.007
    low, high = float(hand[1]), float(hand[1]) + 0.3  # touching at low, far at high
    for _ in range(40):
        mid = 0.5 * (low + high)
        low, high = (low, mid) if clearance(mid) > gap else (mid, high)
    wall = wall_at(high)
    assert clearance(high) == pytest.approx(gap, abs=1e-4)
    camera = CameraSpec(  # looks along the wall's face toward the hand
        position=(hand[0] + 0.5, hand[1] - 0.35, hand[2] + 0.25),
        target=(hand[0], high, hand[2]),
        far=3.0,
        noise=EXACT,
    )
    with PybulletScene(robot, [wall]) as scene:
        scene.set_configuration(robot.home())
        frame = DepthCamera(scene.client, camera).capture()
    grid = OccupancyGrid(SPEC, geometry)
    summary = grid.integrate(frame, state)
    centres = grid.centres()
    assert summary.robot_points > 1000
    on_wall = _objects([wall]).clearance(centres) <= grid.cell
    assert on_wall.all()  # nothing of the arm is mapped
    # Cells of the wall's face inside the padding (12 here; none with the old filter).
    in_padding = geometry.contains(state, centres)
    assert np.count_nonzero(in_padding) >= 5


def test_the_compiled_frame_pass_matches_the_frame_s_own_points(scene, robots) -> None:
    """One compiled pass per frame reads the depth as DepthFrame's numpy code does."""
    from scipy.ndimage import minimum_filter

    from cbp.perception.kernels import eroded_ranges

    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    state = RobotState(robot, robot.home())
    frame = DepthCamera(scene.client, CAMERA).capture()
    grid = OccupancyGrid(SPEC, geometry)
    summary = grid.integrate(frame, state)
    # The readings: the numpy points, less the robot's and those out of range.
    points, hit = frame.points()
    pts = points[hit]
    robot_points = geometry.contains(state, pts, SPEC.robot_margin - geometry.padding)
    kept = pts[~robot_points]
    idx = np.floor((kept - grid.lower) / grid.cell).astype(int)
    inside = np.all((idx >= 0) & (idx < np.array(grid.shape)), axis=1)
    expected = np.zeros(grid.shape, dtype=bool)
    expected[tuple(idx[inside].T)] = True
    np.testing.assert_array_equal(grid.cells == OCCUPIED, expected)
    assert summary.robot_points == np.count_nonzero(robot_points)
    assert summary.inserted == np.count_nonzero(inside)
    assert summary.valid_fraction == pytest.approx(frame.valid().mean())
    # The see-through ranges: NaN says nothing, background is the far plane,
    # eroded over 3 x 3 pixels.
    reference = minimum_filter(
        np.nan_to_num(frame.ranges(), nan=-np.inf, posinf=frame.far),
        size=3,
        mode="nearest",
    )
    nearest, far_plane, far_buffer = frame.buffer_limits
    ranges = eroded_ranges(
        frame.depth, frame.near, frame.far, nearest, far_plane, far_buffer
    )
    np.testing.assert_allclose(ranges, reference, rtol=1e-12)
