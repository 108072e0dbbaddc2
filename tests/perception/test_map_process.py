"""The map in its own process: the same map as the thread's, stamped, and no leaks."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from cbp.collision import CollisionWorld, RobotGeometry
from cbp.perception.map_process import SEGMENT_PREFIX, SLOTS, ProcessMapUpdater
from cbp.perception.mapper import MapUpdater, SnapshotPublisher
from cbp.perception.motion import ApproachEstimator
from cbp.perception.occupancy import OccupancyGrid
from cbp.perception.spec import CameraSpec, PerceptionSpec
from cbp.scenario import ObjectSpec
from cbp.sim.camera import DepthCamera
from cbp.sim.scene import PybulletScene
from cbp.spatial import Pose

BOX = ObjectSpec(
    name="box", shape="box", size=(0.3, 0.1, 0.3), pose=Pose(position=(0.6, 0.0, 0.15))
)
FRONT = CameraSpec(
    name="front",
    position=(0.6, -1.2, 0.3),
    target=(0.6, 0.0, 0.15),
    far=3.0,
    width=64,
    height=48,
)
SIDE = CameraSpec(
    name="side",
    position=(1.8, 0.2, 0.3),
    target=(0.6, 0.2, 0.15),
    far=3.0,
    width=64,
    height=48,
)
SPEC = PerceptionSpec(
    source="depth_camera",
    cameras=[FRONT, SIDE],
    cell_size=0.02,
    bounds=((-0.4, -0.6, -0.02), (1.0, 0.6, 1.0)),
)


@pytest.fixture
def scene(robots):
    """The Panda at home beside a box."""
    robot = robots["panda"]
    with PybulletScene(robot, [BOX]) as scene:
        scene.set_configuration(robot.home())
        yield scene


def _segments() -> list[str]:
    """This process's map segments in /dev/shm."""
    shm = Path("/dev/shm")
    prefix = f"{SEGMENT_PREFIX}{os.getpid()}_"
    return sorted(p.name for p in shm.iterdir() if p.name.startswith(prefix))


def _frames(scene):
    """One small real frame of each camera."""
    return [DepthCamera(scene.client, c).capture() for c in (FRONT, SIDE)]


def _updater(robots, cls, **kwargs):
    """A world, a grid and an updater of class ``cls`` on them."""
    geometry = RobotGeometry(robots["panda"])
    grid = OccupancyGrid(SPEC, geometry)
    world = CollisionWorld(geometry, grid.environment())
    return grid, world, cls(grid, world, **kwargs)


pytestmark = pytest.mark.skipif(
    not Path("/dev/shm").is_dir(), reason="segments are listed in /dev/shm"
)


def test_the_process_publishes_the_map_the_thread_does(scene, robots) -> None:
    """Same frames, same cells and same snapshot; the control side reads the cells."""
    q = robots["panda"].home()
    frames = _frames(scene)
    grid_t, world_t, thread = _updater(robots, MapUpdater, synchronous=True)
    grid_p, world_p, process = _updater(robots, ProcessMapUpdater)
    try:
        for i, frame in enumerate(frames):
            thread.submit(frame, q, 0.1 * (i + 1))
            process.submit(frame, q, 0.1 * (i + 1))
        assert process.wait_idle()
        np.testing.assert_array_equal(grid_p.cells, grid_t.cells)
        mine, theirs = world_p.environment, world_t.environment
        assert mine.blocked is not None
        assert theirs.blocked is not None
        np.testing.assert_array_equal(mine.blocked.mask, theirs.blocked.mask)
        assert sorted(map(tuple, mine.centres)) == sorted(map(tuple, theirs.centres))
        assert process.updates >= 1
        assert process.error is None
        assert process.failed is None
    finally:
        process.close()
        thread.close()


def test_each_snapshot_is_stamped_with_its_newest_frame(scene, robots) -> None:
    """The world's snapshot carries the capture time of the last frame taken in."""
    q = robots["panda"].home()
    _grid, world, process = _updater(robots, ProcessMapUpdater)
    try:
        for t in (0.25, 0.5):
            for frame in _frames(scene):
                process.submit(frame, q, t)
            assert process.wait_idle()
            assert world.environment.stamp == t
            assert process.stamp == t
            assert process.published[-1].stamp == t
            assert process.age() == 0.0
            assert process.hold_reason(0.5) is None
    finally:
        process.close()


def test_the_approach_estimate_runs_in_the_process(scene, robots) -> None:
    """With an estimator the process publishes snapshots all the same."""
    q = robots["panda"].home()
    geometry = RobotGeometry(robots["panda"])
    grid = OccupancyGrid(SPEC, geometry)
    world = CollisionWorld(geometry, grid.environment())
    process = ProcessMapUpdater(grid, world, estimator=ApproachEstimator(world, 1.0))
    try:
        for t in (0.1, 0.2, 0.3):
            for frame in _frames(scene):
                process.submit(frame, q, t)
            assert process.wait_idle()
        assert process.error is None
        assert world.environment.stamp == 0.3
    finally:
        process.close()


def test_a_process_that_dies_holds_the_robot_and_leaks_nothing(scene, robots) -> None:
    """Killed: an error once, a hold for good, submit never waits, close reaps it."""
    q = robots["panda"].home()
    grid, _world, process = _updater(robots, ProcessMapUpdater)
    child = process._process
    assert child is not None
    assert len(_segments()) == 1 + SLOTS + len(SPEC.cameras)
    for frame in _frames(scene):
        process.submit(frame, q, 0.1)
    assert process.wait_idle()
    child.kill()
    assert process._receiver is not None
    process._receiver.join(10.0)
    assert process.failed is not None
    assert "ended" in process.failed
    assert isinstance(process.error, RuntimeError)
    assert "map failed" in (process.hold_reason(0.5) or "")
    for frame in _frames(scene):
        process.submit(frame, q, 0.2)  # returns at once
    assert not process.wait_idle(1.0)
    grid.state_at(np.zeros((1, 3)))  # the cells stay readable
    process.close()
    assert _segments() == []
    process.close()  # twice is harmless


def test_close_frees_every_segment_and_the_process(robots) -> None:
    """After close no segment of this process is left and the child has ended."""
    _, _, process = _updater(robots, ProcessMapUpdater)
    child = process._process
    assert child is not None
    assert child.is_alive()
    assert len(_segments()) == 1 + SLOTS + len(SPEC.cameras)
    process.close()
    assert _segments() == []
    assert process.grid.cells.size > 0  # a copy of the last cells is kept


def test_a_map_behind_the_cameras_holds_the_robot() -> None:
    """Frames submitted more than the timeout after the last snapshot's stamp hold."""
    publisher = SnapshotPublisher()
    publisher.submitted_t, publisher.stamp = 1.0, 0.2
    assert "behind the cameras" in (publisher.hold_reason(0.5) or "")
    publisher.stamp = 0.6
    assert publisher.hold_reason(0.5) is None


SMALL_CAMERA = (
    "[{name: head, position: [-0.35, 0.0, 1.15], target: [0.55, 0.0, 0.15],"
    " width: 64, height: 48, fov_deg: 70.0, far: 2.5}]"
)


def _run(overrides: dict[str, str]):
    """The pushed-box scene seen by one small camera, wall clock."""
    from cbp.data import data_dir
    from cbp.run import build_run
    from cbp.scenario import load_scenario

    path = data_dir("scenarios") / "cat_pushed_obstacle.yaml"
    scenario = load_scenario(
        path,
        overrides={
            "perception.source": "depth_camera",
            "perception.cameras": SMALL_CAMERA,
            "perception.cell_size": "0.02",
        }
        | overrides,
    )
    return build_run(scenario, method="cat", clock="wall")


def test_a_run_whose_map_process_dies_holds_the_robot() -> None:
    """The executors' run: an event at the next frames, and a hold for good."""
    run = _run({"perception.map_process": "true"})
    try:
        assert run.cameras is not None
        mapper = run.cameras.mapper
        assert isinstance(mapper, ProcessMapUpdater)
        run.advance(0.2)
        assert mapper.wait_idle()
        assert run.hold_reason(0.2) is None
        assert mapper._process is not None
        mapper._process.kill()
        assert mapper._receiver is not None
        mapper._receiver.join(10.0)
        run.advance(0.4)
        assert any("map update" in m and "ended" in m for _, m in run.log.events)
        assert "map failed" in (run.hold_reason(0.4) or "")
    finally:
        run.finish()
    assert _segments() == []


def test_the_setting_chooses_the_updater() -> None:
    """perception.map_process picks the process in wall-clock runs, else the thread."""
    for setting, kind in (("true", ProcessMapUpdater), ("false", MapUpdater)):
        run = _run({"perception.map_process": setting})
        try:
            assert run.cameras is not None
            assert type(run.cameras.mapper) is kind
        finally:
            run.finish()
    assert _segments() == []


@pytest.mark.slow
def test_a_wall_clock_run_with_the_map_process_publishes_and_cleans_up() -> None:
    """The pushed box, five cameras, wall clock: snapshots all along, no leaks.

    (The contact force of a wall-clock run depends on the machine's load:
    ``benchmarks/map_latency.py`` measures it; here the plumbing.)
    """
    from cbp.data import data_dir
    from cbp.executors.cat import run_cat
    from cbp.scenario import load_scenario

    path = data_dir("scenarios") / "cat_pushed_obstacle.yaml"
    overrides = {
        "perception.source": "depth_camera",
        "perception.map_process": "true",
        "duration": "2.0",
    }
    trace = run_cat(load_scenario(path, overrides=overrides))
    messages = [m for _, m in trace.events]
    assert not any("map failed" in m or "map update" in m for m in messages)
    assert trace.aborted is None
    assert _segments() == []


@pytest.mark.slow
def test_moving_clusters_keep_the_pushed_box_off_in_virtual_time() -> None:
    """cluster_motion on: the box pushed at 10 cm/s, seen by the cameras, 0 N."""
    from cbp.data import data_dir
    from cbp.executors.cat import run_cat
    from cbp.metrics import run_metrics
    from cbp.scenario import load_scenario

    path = data_dir("scenarios") / "cat_pushed_obstacle.yaml"
    overrides = {
        "perception.source": "depth_camera",
        "perception.cluster_motion": "true",
        "method.cat.timing.clock": "virtual",
        "world.objects.box.motion": "{velocity: [0.0, -0.1, 0.0], start: 0.5,"
        " stop: 2.5}",
        "duration": "4.0",
    }
    m = run_metrics(run_cat(load_scenario(path, overrides=overrides)))
    assert m["peak_contact_force_n"] == 0.0, m
