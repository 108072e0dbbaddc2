"""The three-state map: unseen space is an obstacle, seen space is free, cameras merge."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cbp.collision import CollisionWorld, OccupancyEnvironment, RobotGeometry
from cbp.collision.checker import FreeSpaceChecker
from cbp.perception.frame import DepthFrame
from cbp.perception.kernels import FREE, OCCUPIED, UNKNOWN
from cbp.perception.mapper import MapUpdater
from cbp.perception.moving import moving_growth, with_moving
from cbp.perception.occupancy import OccupancyGrid
from cbp.perception.spec import CameraSpec, DepthNoise, PerceptionSpec
from cbp.run.events import RunLog
from cbp.run.separation import SeparationMonitor
from cbp.scenario import ObjectSpec
from cbp.sim.camera import DepthCamera
from cbp.sim.scene import PybulletScene
from cbp.spatial import Pose
from cbp.state import RobotState

BOX = ObjectSpec(
    name="box",
    shape="box",
    size=(0.3, 0.1, 0.3),
    pose=Pose(position=(0.6, 0.0, 0.15)),
)
#: Frames exactly as rendered: these tests check the map's logic (the noise
#: model has its own, tests/sim/test_depth_noise.py).
EXACT = DepthNoise(enabled=False)
# Looking along +y at the box: behind it (y > 0.05) is its shadow, which the
# side camera (looking along -x) sees.
FRONT = CameraSpec(
    name="front",
    position=(0.6, -1.2, 0.3),
    target=(0.6, 0.0, 0.15),
    far=3.0,
    noise=EXACT,
)
SIDE = CameraSpec(
    name="side",
    position=(1.8, 0.2, 0.3),
    target=(0.6, 0.2, 0.15),
    far=3.0,
    noise=EXACT,
)
SPEC = PerceptionSpec(
    source="depth_camera",
    cameras=[FRONT],
    cell_size=0.02,
    bounds=((-0.4, -0.6, -0.02), (1.0, 0.6, 1.0)),
)
BEHIND = np.array([[0.6, 0.2, 0.15]])  # in the box's shadow from FRONT
BEFORE = np.array([[0.6, -0.35, 0.15]])  # between the camera and the box
IN_BOX = np.array([[0.6, 0.0, 0.15]])
FRONT_FACE = np.array([[0.6, -0.06, 0.15]])


@pytest.fixture
def scene(robots):
    robot = robots["panda"]
    with PybulletScene(robot, [BOX]) as scene:
        scene.set_configuration(robot.home())
        yield scene


def test_cells_start_unknown_and_frames_sort_them(scene, robots) -> None:
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    grid = OccupancyGrid(SPEC, geometry)
    assert grid.count(UNKNOWN) == grid.cells.size
    state = RobotState(robot, robot.home())
    summary = grid.integrate(DepthCamera(scene.client, FRONT).capture(), state)
    assert summary.valid_fraction == 1.0
    assert summary.seen > 1000
    assert summary.carved > 100
    assert grid.state_at(BEFORE)[0] == FREE
    assert grid.state_at(BEHIND)[0] == UNKNOWN
    # The box's front face is occupied; its inside was never seen.
    assert grid.state_at(FRONT_FACE)[0] == OCCUPIED
    assert grid.state_at(IN_BOX)[0] == UNKNOWN
    # The robot's space is free, though the camera sees only its front.
    hand = state.data.oMf[robot.frame_id("panda_link4")].translation
    assert grid.state_at(hand[None])[0] == FREE


def test_unknown_space_blocks_unless_set_free(scene, robots) -> None:
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    state = RobotState(robot, robot.home())
    frame = DepthCamera(scene.client, FRONT).capture()
    for unknown, blocked in (("occupied", True), ("free", False)):
        grid = OccupancyGrid(replace(SPEC, unknown=unknown), geometry)
        grid.integrate(frame, state)
        env = grid.environment()
        assert bool(env.inside(BEHIND)[0]) is blocked
        assert not env.inside(BEFORE)[0]
        # Only the shell is indexed: far fewer cells than the blocked volume.
        assert len(env) < int(env.blocked.mask.sum()) or not blocked


def test_a_second_camera_sees_the_shadow_free(scene, robots) -> None:
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    grid = OccupancyGrid(replace(SPEC, cameras=[FRONT, SIDE]), geometry)
    world = CollisionWorld(geometry, grid.environment())
    updater = MapUpdater(grid, world)
    try:
        q = robot.home()
        updater.submit(DepthCamera(scene.client, FRONT).capture(), q)
        updater.submit(DepthCamera(scene.client, SIDE).capture(), q)
        assert updater.wait_idle()
    finally:
        updater.close()
    assert grid.frames == 2
    assert grid.state_at(BEHIND)[0] == FREE
    assert not world.environment.inside(BEHIND)[0]


def test_space_outside_the_bounds_is_unknown_never_free(robots) -> None:
    """A box wholly below the map's floor is an obstacle, seen or not.

    Cameras see through the space outside the bounds to it, and the robot's
    first frame frees two cells around it, up to the floor: the layer of cells
    around the bounds stays unknown, the snapshot holds it as an obstacle, and
    points beyond the grid are in an obstacle too (``unknown: free``: none).
    """
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    below = ObjectSpec(
        name="below",
        shape="box",
        size=(0.3, 0.3, 0.1),
        pose=Pose(position=(0.6, 0.0, -0.2)),
    )
    home = robot.home()
    with PybulletScene(robot, [below]) as scene:
        scene.set_configuration(home)
        frame = DepthCamera(scene.client, FRONT).capture()
    state = RobotState(robot, home)
    for unknown, blocked in (("occupied", True), ("free", False)):
        grid = OccupancyGrid(replace(SPEC, unknown=unknown), geometry)
        grid.integrate(frame, state)
        lower, upper = grid.bounds
        np.testing.assert_allclose(lower, SPEC.region[0])
        assert np.all(upper >= SPEC.region[1])
        layer = np.ones(grid.shape, dtype=bool)
        layer[1:-1, 1:-1, 1:-1] = False
        assert not np.any(grid.cells[layer] == FREE)
        assert grid.state_at(BEFORE)[0] == FREE  # inside, seen through
        box = np.array([[0.6, 0.0, -0.16], [0.6, -0.1, -0.2], [0.6, 0.0, -5.0]])
        assert np.all(grid.state_at(box) == UNKNOWN)
        env = grid.environment()
        assert env.inside(box).tolist() == [blocked] * 3
        floor = np.array([[0.6, -0.35, lower[2] - 0.5 * grid.cell]])
        assert bool(env.inside(floor)[0]) is blocked
        # The floor's layer under the space seen free is in the shell.
        shell = env.centres
        assert bool(np.any(shell[:, 2] < lower[2])) is blocked


def _shell_from_scratch(grid: OccupancyGrid) -> set[tuple[int, int, int]]:
    """The obstacle cells with a neighbour inside the grid that is not blocked."""
    blocked = (grid.cells == OCCUPIED) | (
        (grid.cells == UNKNOWN) & grid.spec.unknown_blocks
    )
    open_next = np.zeros_like(blocked)
    for axis in range(3):
        for shift in (1, -1):
            moved = np.roll(~blocked, shift, axis=axis)
            edge = [slice(None)] * 3
            edge[axis] = 0 if shift == 1 else -1
            moved[tuple(edge)] = False  # no wrap-around: outside the grid
            open_next |= moved
    return {tuple(map(int, ijk)) for ijk in np.argwhere(blocked & open_next)}


def test_each_snapshot_is_the_shell_of_the_whole_map(scene, robots) -> None:
    """Snapshots rescan only changed bricks; they match a full rescan each time.

    Two cameras, an arm that moves between frames (its old space stays free,
    its new space is carved), and the box removed and seen through until its
    cells clear.
    """
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    grid = OccupancyGrid(replace(SPEC, misses_to_clear=2), geometry)
    rng = np.random.default_rng(3)
    q = robot.home()
    snapshots = 0
    for step in range(8):
        if step == 4:
            scene.remove_object("box")
        q = np.clip(
            q + rng.uniform(-0.3, 0.3, q.shape), robot.lower_limits, robot.upper_limits
        )
        scene.set_configuration(q)
        state = RobotState(robot, q)
        for camera in (FRONT, SIDE) if step % 2 else (FRONT,):
            grid.integrate(DepthCamera(scene.client, camera).capture(), state)
        env = grid.environment()
        cells = np.floor((env.centres - grid.lower) / grid.cell).astype(int)
        got = {tuple(map(int, ijk)) for ijk in cells}
        assert len(got) == len(env.centres)  # no cell twice
        assert got == _shell_from_scratch(grid), step
        assert np.array_equal(env.blocked.mask, grid.cells != FREE)
        snapshots += 1
    assert grid.state_at(IN_BOX)[0] == FREE  # the removed box cleared
    assert snapshots == 8


def test_the_checker_finds_a_shape_wholly_inside_unknown_space(robots) -> None:
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    grid = OccupancyGrid(SPEC, geometry)
    home = robot.home()
    grid.carve_robot(RobotState(robot, home))  # nothing seen: only the robot's space
    env = grid.environment()
    checker = FreeSpaceChecker(geometry, env, padding=0.0, self_collision=False)
    assert checker.is_free(home)
    moved = home.copy()
    moved[0] += 1.5  # the whole arm swings into space nothing has seen
    assert not checker.is_free(moved)
    world = CollisionWorld(geometry, env)
    assert world.check(home).penetration == 0.0


@pytest.mark.parametrize("seen", [False, True])
def test_the_planners_check_against_a_map_is_cats_step_validation(
    scene, robots, seen: bool
) -> None:
    """``is_free`` against a map answers as CAT's ``check(q).accepted``, inside too."""
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    grid = OccupancyGrid(replace(SPEC, cell_size=0.01), geometry)
    home = robot.home()
    state = RobotState(robot, home)
    grid.carve_robot(state)
    if seen:  # the box and the space before it; its shadow stays unseen
        grid.integrate(DepthCamera(scene.client, FRONT).capture(), state)
    world = CollisionWorld(geometry, grid.environment())
    rng = np.random.default_rng(3)
    qs = [
        np.clip(
            home + rng.uniform(-s, s, robot.nq), robot.lower_limits, robot.upper_limits
        )
        for s in (0.05, 0.3, 1.0)
        for _ in range(150)
    ]
    free = np.array([world.is_free(q) for q in qs])
    accepted = np.array([world.check(q).accepted for q in qs])
    assert np.array_equal(free, accepted)
    assert 0 < free.sum() < len(qs)  # both answers are tried
    inside = home.copy()
    inside[0] += 1.5  # the whole arm swings into space nothing has seen
    assert not world.is_free(inside)
    assert not world.is_free(np.full(robot.nq, np.nan))


def test_frames_without_valid_readings_change_nothing(scene, robots) -> None:
    robot = robots["panda"]
    grid = OccupancyGrid(SPEC, RobotGeometry(robot))
    good = DepthCamera(scene.client, FRONT).capture()
    for fill in (np.nan, 0.0 * np.nan + np.inf, -1.0):
        bad = DepthFrame(
            np.full_like(good.depth, fill),
            good.view,
            good.projection,
            good.near,
            good.far,
            "front",
        )
        summary = grid.integrate(bad, None)
        assert summary.valid_fraction == 0.0
        assert summary.inserted == 0
        assert summary.seen == 0
    assert grid.count(UNKNOWN) == grid.cells.size


def test_a_mounted_camera_follows_its_link(scene, robots) -> None:
    robot = robots["panda"]
    spec = CameraSpec(
        name="wrist",
        parent="panda_hand",
        noise=EXACT,
        offset=Pose(position=(0.06, 0.0, 0.03), rpy_deg=(0.0, 25.0, 0.0)),
        near=0.05,
    )
    camera = DepthCamera(scene.client, spec, robot)
    state = RobotState(robot, robot.home())
    frame = camera.capture(state)
    expected = state.data.oMf[robot.frame_id("panda_hand")] * spec.offset.to_se3()
    np.testing.assert_allclose(frame.position, expected.translation, atol=1e-9)
    # The optical axis is the offset frame's +z: the image centre's ray.
    centre = frame.project((expected.translation + 0.5 * expected.rotation[:, 2])[None])
    rows, cols = centre[0][0], centre[1][0]
    assert abs(rows - spec.height / 2) <= 1
    assert abs(cols - spec.width / 2) <= 1
    moved = robot.home()
    moved[0] += 0.5
    state.update(moved)
    assert not np.allclose(camera.capture(state).position, frame.position)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"parent": None}, "needs 'position' and 'target'"),
        ({"position": (0.0, 0.0, 1.0)}, "takes 'offset'"),
    ],
)
def test_camera_poses_are_checked(changes, message) -> None:
    from cbp.errors import ConfigError

    base = {"name": "c", "parent": "panda_hand"}
    with pytest.raises(ConfigError, match=message):
        CameraSpec(**{**base, **changes})


def test_a_surface_nearer_than_the_minimum_range_is_not_seen_through(
    scene, robots
) -> None:
    """A box 3 cm before a camera whose range starts at 5 cm: no reading.

    And no view past it: a renderer's clipping plane would show what is behind
    the box, and the map would free the box's cells.
    """
    robot = robots["panda"]
    close = CameraSpec(
        name="close",
        noise=EXACT,
        position=(0.6, -0.08, 0.15),  # the box's front face is at y = -0.05
        target=(0.6, 1.0, 0.15),
        near=0.05,
        far=3.0,
        fov_deg=30.0,
    )
    frame = DepthCamera(scene.client, close).capture()
    h, w = frame.depth.shape
    assert not frame.valid()[h // 2, w // 2]
    assert np.isnan(frame.ranges()[h // 2, w // 2])
    assert frame.problem(0.5) is None  # a close reading: the camera works
    grid = OccupancyGrid(replace(SPEC, cameras=[close]), RobotGeometry(robot))
    grid.integrate(frame, None)
    inside = np.array([[0.6, y, 0.15] for y in (-0.01, 0.01, 0.03)])
    assert np.all(grid.state_at(inside) == UNKNOWN)


def test_the_far_plane_reads_as_nothing_seen_with_a_near_clipping_plane(
    scene,
) -> None:
    """The far plane is background, not invalid, with a near clipping plane.

    With a clipping plane of millimetres it comes back as 1.0000001.
    """
    up = CameraSpec(
        name="up",
        position=(0.0, 0.0, 1.2),
        target=(0.0, 0.0, 3.0),
        up=(1.0, 0.0, 0.0),
        noise=EXACT,
    )
    frame = DepthCamera(scene.client, up).capture()
    assert frame.near < up.near
    assert np.all(frame.valid())
    assert np.all(np.isinf(frame.ranges()))


def _creep(robots, robot_space: str) -> float:
    """Turn joint 1 toward space no camera sees while the arm stays clear of it.

    Each 0.5 degree step is taken only when the padded arm would be clear of
    every obstacle cell of the map as it stands, and the robot's space is then
    freed as a frame would free it. Returns how far the arm got [rad].
    """
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    grid = OccupancyGrid(
        replace(SPEC, cell_size=0.01, robot_space=robot_space), geometry
    )
    q = robot.home()
    grid.carve_robot(RobotState(robot, q))
    step = np.radians(0.5)
    for _ in range(120):
        ahead = q.copy()
        ahead[0] += step
        world = CollisionWorld(geometry, grid.environment())
        contacts = world.contacts(RobotState(robot, ahead)).environment_part()
        if len(contacts.distance) and contacts.distance.min() < 0.0:
            break
        q = ahead
        grid.carve_robot(RobotState(robot, q))
    return float(q[0] - robot.home()[0])


def test_the_robot_never_frees_space_it_has_not_held(robots) -> None:
    """No camera sees anything: the arm may not creep into the unseen space.

    With ``robot_space: nearby`` each frame freed centimetres beyond where the
    arm may stand, so it could turn on into space nothing had seen (and into an
    obstacle hidden there); with ``held`` it stops within the space it started
    in (the padded shapes and two cells).
    """
    assert _creep(robots, "held") < np.radians(3.0)
    assert _creep(robots, "nearby") == pytest.approx(np.radians(60.0))


# A plate between FRONT and BEFORE, added after the camera saw BEFORE free.
PLATE = ObjectSpec(
    name="plate",
    shape="box",
    size=(0.3, 0.02, 0.3),
    pose=Pose(position=(0.6, -0.6, 0.15)),
)


def _plate_comes_between(
    scene, robots, spec: PerceptionSpec, moved: bool = False, plate: ObjectSpec = PLATE
):
    """Two frames of FRONT, the plate added between them; the grid after."""
    robot = robots["panda"]
    grid = OccupancyGrid(spec, RobotGeometry(robot))
    state = RobotState(robot, robot.home())
    grid.integrate(DepthCamera(scene.client, FRONT).capture(), state, 0.0)
    assert grid.state_at(BEFORE)[0] == FREE
    scene.add_object(plate, plate.pose.to_se3())
    camera = replace(FRONT, position=(0.61, -1.2, 0.3)) if moved else FRONT
    try:
        frame = DepthCamera(scene.client, camera).capture()
    finally:
        scene.remove_object("plate")
    return grid, grid.integrate(frame, state, 0.1), state


def test_space_hidden_by_something_that_came_between_is_unknown(scene, robots) -> None:
    """What the camera saw free and an obstacle now hides may hold the obstacle."""
    grid, summary, state = _plate_comes_between(scene, robots, SPEC)
    assert summary.hidden > 100
    assert grid.state_at(BEFORE)[0] == UNKNOWN
    # Up to the robot only: the space it holds stays free.
    hand = state.data.oMf[state.robot.frame_id("panda_link4")].translation
    assert grid.state_at(hand[None])[0] == FREE
    # Not tracked: hidden space keeps the state it was last seen in.
    for spec in (replace(SPEC, shadow_hold=0.0),):
        grid, summary, _ = _plate_comes_between(scene, robots, spec)
        assert summary.hidden == 0
        assert grid.state_at(BEFORE)[0] == FREE


def test_a_camera_that_moved_hides_nothing(scene, robots) -> None:
    """Ranges along a pixel compare only from one pose (a camera on a link)."""
    grid, summary, _ = _plate_comes_between(scene, robots, SPEC, moved=True)
    assert summary.hidden == 0
    assert grid.state_at(BEFORE)[0] == FREE


def test_a_camera_on_the_robot_hides_nothing(scene, robots) -> None:
    """Its view moves with the arm: it keeps no pixel history."""
    on_hand = CameraSpec(name="front", parent="panda_hand", noise=EXACT)
    spec = replace(SPEC, cameras=[on_hand])
    grid, summary, _ = _plate_comes_between(scene, robots, spec)
    assert summary.hidden == 0
    assert grid.state_at(BEFORE)[0] == FREE


def test_a_static_scene_hides_nothing(scene, robots) -> None:
    robot = robots["panda"]
    grid = OccupancyGrid(replace(SPEC, cameras=[FRONT, SIDE]), RobotGeometry(robot))
    camera = {c.name: DepthCamera(scene.client, c) for c in (FRONT, SIDE)}
    for k, q in enumerate(np.linspace(robot.home(), robot.home() + 0.3, 6)):
        scene.set_configuration(q)
        state = RobotState(robot, q)
        for name in ("front", "side"):
            summary = grid.integrate(camera[name].capture(), state, 0.1 * k)
            assert summary.hidden == 0, (k, name)


#: The plate inside the map's bounds (PLATE's face toward the camera is not).
INNER_PLATE = replace(PLATE, pose=Pose(position=(0.6, -0.45, 0.15)))


def test_cells_something_entered_are_moving_for_a_while(scene, robots) -> None:
    """Readings nearer than the space seen free mark moving cells, for shadow_hold."""
    grid, _, _ = _plate_comes_between(scene, robots, SPEC, plate=INNER_PLATE)
    moving = grid.moving_centres(0.1)
    assert len(moving) > 20
    # The plate's face toward the camera, and nothing else.
    y = INNER_PLATE.pose.position[1]
    assert np.all(np.abs(moving[:, 1] - y) <= 0.01 + SPEC.cell_size)
    assert len(grid.moving_centres(0.1 + SPEC.shadow_hold + 0.05)) == 0
    # A camera on the robot, or one that moved, tells nothing of what moves.
    for moved, spec in (
        (True, SPEC),
        (False, replace(SPEC, cameras=[CameraSpec(name="front", parent="panda_hand")])),
    ):
        grid, _, _ = _plate_comes_between(
            scene, robots, spec, moved=moved, plate=INNER_PLATE
        )
        assert len(grid.moving_centres(0.1)) == 0


def test_a_static_scene_has_no_moving_cells(scene, robots) -> None:
    robot = robots["panda"]
    grid = OccupancyGrid(replace(SPEC, cameras=[FRONT, SIDE]), RobotGeometry(robot))
    camera = {c.name: DepthCamera(scene.client, c) for c in (FRONT, SIDE)}
    for k, q in enumerate(np.linspace(robot.home(), robot.home() + 0.3, 6)):
        scene.set_configuration(q)
        state = RobotState(robot, q)
        for name in ("front", "side"):
            grid.integrate(camera[name].capture(), state, 0.1 * k)
    assert len(grid.moving_centres(0.5)) == 0


def _plate_before_the_hand(scene, robots):
    """FRONT sees the hand, then a plate between them: grid, world, state, plate."""
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    grid = OccupancyGrid(SPEC, geometry)
    state = RobotState(robot, robot.home())
    grid.integrate(DepthCamera(scene.client, FRONT).capture(), state, 0.0)
    hand = state.data.oMf[robot.frame_id("panda_hand")].translation
    plate = replace(PLATE, pose=Pose(position=(hand[0], -0.25, hand[2])))
    scene.add_object(plate, plate.pose.to_se3())
    try:
        grid.integrate(DepthCamera(scene.client, FRONT).capture(), state, 0.1)
    finally:
        scene.remove_object("plate")
    return grid, CollisionWorld(geometry, grid.environment()), state, plate


def test_moving_cells_are_met_ahead_and_unseen_space_gives_way(scene, robots) -> None:
    """The moving cells' contacts come growth nearer; unknown ones drop out then."""
    grid, world, state, plate = _plate_before_the_hand(scene, robots)
    mapped = grid.environment()
    centres = grid.moving_centres(0.1)
    assert len(centres)
    still = world.query(state)
    unknown = grid.state_at(still.other_point - 0.25 * grid.cell * still.normal)
    assert np.any(unknown == UNKNOWN)  # the plate's shadow reaches the hand
    # Far ahead (0.3 m): the plate's cells reach the hand's margin.
    ahead = with_moving(mapped, centres, 0.3, grid.cells, grid.lower)
    met = world.query(state, ahead)
    inner = met.other_point - 0.25 * grid.cell * met.normal
    assert not np.any(grid.state_at(inner) == UNKNOWN)
    near_plate = np.abs(met.other_point[:, 1] - plate.pose.position[1]) < 0.03
    assert np.any(near_plate)
    assert np.min(met.distance[near_plate]) < np.min(met.distance) + 1e-9
    # Not far enough ahead to reach: the map's contacts as they were.
    short = world.query(
        state, with_moving(mapped, centres, 0.01, grid.cells, grid.lower)
    )
    assert len(short) == len(still)
    np.testing.assert_allclose(np.sort(short.distance), np.sort(still.distance))


def test_step_validation_measures_moving_cells_where_they_are(scene, robots) -> None:
    """Grown into the arm, the moving cells constrain it but do not refuse steps.

    The contact rows keep the arm out of where the plate may come; a step is
    refused only by where it is (before, a step out of one box's growth and
    into another's was refused, and two boxes held the arm: moving_11).
    """
    grid, world, state, _ = _plate_before_the_hand(scene, robots)
    centres = grid.moving_centres(0.1)
    ahead = with_moving(grid.environment(), centres, 0.3, grid.cells, grid.lower)
    world.set_environment(ahead)
    check = world.check(state.q)
    assert check.contacts.penetration > 0.1  # 0.3 m nearer: deep in the growth
    assert check.contacts.lead is not None
    assert check.contacts.lead.max() == pytest.approx(0.3)
    # Where the plate is, nothing touches the hand: the step is kept.
    assert check.accepted
    assert check.penetration == pytest.approx(check.contacts.present_penetration)
    assert check.penetration < 0.01


def test_the_separation_monitor_says_when_a_moving_obstacle_is_too_near(
    scene, robots
) -> None:
    """Once when the separation is short, once when it is 1 cm beyond again."""
    grid, world, state, _ = _plate_before_the_hand(scene, robots)
    mapped = grid.environment()
    centres = grid.moving_centres(0.1)
    plate = OccupancyEnvironment(centres, grid.cell)
    reach = plate.query(world.placed_apart(state), 1.0, 3).distance
    # As the monitor measures it: beyond the padding and half a cell.
    nearest = float(np.min(reach)) - world.padding - plate.resolution
    log = RunLog("cat")
    monitor = SeparationMonitor(world, log, 0.25)

    def check(t: float, growth: float | None) -> bool:
        env = (
            mapped
            if growth is None
            else with_moving(mapped, centres, growth, grid.cells, grid.lower)
        )
        world.set_environment(env)
        monitor.check(t, state.q)
        return monitor.short

    assert not check(0.1, 0.01)
    assert check(0.2, nearest + 0.02)
    assert check(0.3, nearest + 0.02)
    assert len(log.events) == 1
    assert "the cameras see moving" in log.events[0][1]
    # Within 1 cm beyond the separation it stays short; beyond, it is clear.
    assert check(0.4, nearest - 0.005)
    assert len(log.events) == 1
    assert not check(0.5, None)
    assert "clear of the arm again" in log.events[-1][1]
    assert monitor.times_short == 1


def test_moving_cells_grow_in_whole_centimetres_and_only_with_a_look_ahead() -> None:
    assert moving_growth(0.25, 0.3, 0.0) == pytest.approx(0.08)
    assert moving_growth(0.25, 0.3, 0.1) == pytest.approx(0.10)
    assert moving_growth(0.25, 0.0, 0.5) == 0.0  # JT plans nothing ahead
    assert moving_growth(0.0, 0.3, 0.0) == 0.0


def test_a_snapshot_older_than_the_grid_is_read_with_the_newest_states(
    scene, robots
) -> None:
    """Unknown cells a newer frame saw through do not hold the arm either.

    A map in its own process publishes snapshots older than its grid: the
    states looked up are the grid's newest, and a cell free there is no
    obstacle (it held the arm while obstacles came, in wall-clock runs).
    """
    grid, world, state, _ = _plate_before_the_hand(scene, robots)
    mapped = grid.environment()
    centres = grid.moving_centres(0.1)
    still = world.query(state)
    inner = still.other_point - 0.25 * grid.cell * still.normal
    shadow = grid.state_at(inner) == UNKNOWN
    assert np.any(shadow)
    # A newer frame saw through the shadow: the grid moved on, the snapshot not.
    newer = grid.cells.copy()
    seen = np.floor((inner[shadow] - grid.lower) / grid.cell).astype(np.intp)
    newer[seen[:, 0], seen[:, 1], seen[:, 2]] = FREE
    met = world.query(state, with_moving(mapped, centres, 0.3, newer, grid.lower))
    assert len(met)
    cells = np.floor(
        (met.other_point - 0.25 * grid.cell * met.normal - grid.lower) / grid.cell
    ).astype(np.intp)
    held = {tuple(c) for c in cells}
    assert not held & {tuple(c) for c in seen}
    # The snapshot itself, read alone, still holds them (it is as it was).
    assert np.any(grid.state_at(inner[shadow]) == UNKNOWN)


def test_a_virtual_map_with_latency_installs_each_snapshot_that_much_later(
    scene, robots
) -> None:
    """perception.virtual_latency: a snapshot reaches the world at capture + latency."""
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    grid = OccupancyGrid(SPEC, geometry)
    world = CollisionWorld(geometry, grid.environment())
    before = world.environment
    updater = MapUpdater(grid, world, synchronous=True, latency=0.05)
    updater.look_ahead = 0.1
    updater.submit(DepthCamera(scene.client, FRONT).capture(), robot.home(), 0.1)
    assert world.environment is before
    assert updater.updates == 0
    updater.release(0.149)
    assert world.environment is before
    updater.release(0.15)
    assert world.environment is not before
    assert world.environment.stamp == 0.1
    assert updater.stamp == 0.1
    assert updater.updates == 1
    # Without latency, at once (as virtual time always did).
    now = MapUpdater(grid, world, synchronous=True)
    now.submit(DepthCamera(scene.client, FRONT).capture(), robot.home(), 0.2)
    assert now.updates == 1
    assert now.stamp == 0.2


def test_the_moving_cells_tables_are_built_before_a_run(robots) -> None:
    """Every reach a moving cell's query takes within the horizon is kept beforehand."""
    from cbp.collision.shape_table import ShapeTable
    from cbp.perception.moving import REACH_STEP, prepare_moving_tables

    geometry = RobotGeometry(robots["panda"])
    cell, margin, speed, horizon = 0.01, 0.065, 0.25, 1.1
    reaches = prepare_moving_tables(geometry.shapes, margin, cell, speed, horizon)
    assert reaches == sorted(reaches)
    assert len(reaches) >= 5  # 6.5 cm to 34 cm in 5 cm steps
    probe = OccupancyEnvironment(np.zeros((1, 3)), cell)
    probe.reach_step = REACH_STEP  # as the moving cells' environment rounds
    for look_ahead in np.linspace(0.0, 0.6, 7):
        for age in np.linspace(0.0, horizon - look_ahead, 7):
            growth = moving_growth(speed, look_ahead, age)
            reach = probe.table_reach(margin + growth)
            assert reach in reaches
            assert ShapeTable.kept(geometry.shapes, reach) is not None
    assert prepare_moving_tables(geometry.shapes, margin, cell, 0.0, horizon) == []
