"""Frames that lie are not believed: blind, frozen, or seeing through the robot.

Real frames of a Panda beside a table rendered by PyBullet, then altered the
way a failing sensor or a bumped camera alters them.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cbp.perception.frame import DepthFrame
from cbp.perception.occupancy import OccupancyGrid
from cbp.perception.plausibility import EXPECTED_IN_VIEW, FrameCheck, PlausibilityLimits
from cbp.perception.spec import CameraSpec, PerceptionSpec
from cbp.scenario import ObjectSpec
from cbp.sim.camera import DepthCamera
from cbp.sim.scene import PybulletScene
from cbp.spatial import Pose
from cbp.state import RobotState

TABLE = ObjectSpec(
    name="table", shape="box", size=(0.6, 1.0, 0.04), pose=Pose(position=(0.6, 0, 0.18))
)
CAMERA = CameraSpec(
    position=(1.6, 0.0, 1.1), target=(0.3, 0.0, 0.4), far=3.0, width=160, height=120
)
LIMITS = PlausibilityLimits()


@pytest.fixture
def seen(robots):
    """The robot, a fixed camera looking at it, its frame and the joints."""
    robot = robots["panda"]
    with PybulletScene(robot, [TABLE]) as scene:
        q = robot.home()
        scene.set_configuration(q)
        camera = DepthCamera(scene.client, CAMERA, robot)
        yield robot, scene, camera, q


def _joints(robot, q):
    state = RobotState(robot, q)
    return np.array([m.translation for m in list(state.data.oMi)[1:]])


def test_a_true_frame_is_believed_and_so_is_the_next(seen) -> None:
    """A camera that sees the arm where it is: no problem, frame after frame."""
    robot, _, camera, q = seen
    check = FrameCheck("side", mounted=False, limits=LIMITS)
    assert check.check(camera.capture(), q, _joints(robot, q)) is None
    assert check.check(camera.capture(), q, _joints(robot, q)) is None  # arm still


def test_a_blind_frame_that_reads_nothing_is_refused(seen) -> None:
    """Nothing up to the far plane everywhere: refused, though well formed."""
    robot, _, camera, q = seen
    frame = camera.capture()
    blind = dataclasses.replace(frame, depth=np.ones_like(frame.depth))
    assert blind.problem(0.2) is None  # well formed: every pixel reads
    problem = FrameCheck("side", False, LIMITS).check(blind, q, _joints(robot, q))
    assert problem is not None
    assert "far plane in 100.0% of its pixels" in problem


def test_a_frozen_frame_is_refused_only_when_the_arm_moved_in_view(seen) -> None:
    """The same image again: fine while nothing moved, refused once the arm did."""
    robot, scene, camera, q = seen
    check = FrameCheck("side", False, LIMITS)
    frame = camera.capture()
    assert check.check(frame, q, _joints(robot, q)) is None
    assert check.check(frame, q, _joints(robot, q)) is None  # nothing moved
    moved = q.copy()
    moved[0] += 0.3
    problem = check.check(frame, moved, _joints(robot, moved))
    assert problem is not None
    assert problem.startswith("frozen")
    # Stuck: the arm stopped for it, and its image is still refused.
    still = check.check(frame, moved, _joints(robot, moved))
    assert still is not None
    assert still.startswith("frozen")
    scene.set_configuration(moved)  # a live sensor shows the arm where it went
    assert check.check(camera.capture(), moved, _joints(robot, moved)) is None


def _shifted(view: np.ndarray) -> np.ndarray:
    """A camera's view 5 cm to the side."""
    out = view.copy()
    out[0, 3] += 0.05
    return out


def test_a_camera_on_the_arm_looking_into_open_space_is_not_frozen(seen) -> None:
    """Nothing up to the far plane, the same again while it moves: believed.

    No motion could change such an image (the wrist camera of cat_wrist_limit
    with exact frames turns up into open space); where the map holds
    obstacles in its view, the far-plane check refuses it.
    """
    robot, _, camera, q = seen
    frame = camera.capture()
    open_space = dataclasses.replace(frame, depth=np.ones_like(frame.depth))
    check = FrameCheck("wrist", True, LIMITS)
    joints = _joints(robot, q)
    assert check.check(open_space, q, joints, lambda f: 0.0) is None
    moved = dataclasses.replace(open_space, view=_shifted(open_space.view))
    assert check.check(moved, q, joints, lambda f: 0.0) is None
    # The same image of something while the camera moved: frozen.
    check.check(frame, q, joints, lambda f: 0.0)
    again = dataclasses.replace(frame, view=_shifted(frame.view))
    problem = check.check(again, q, joints, lambda f: 0.0)
    assert problem is not None
    assert problem.startswith("frozen")


def test_a_bumped_camera_sees_through_the_robot_and_is_refused(seen) -> None:
    """Turned by 20 degrees, its frame still claims the old pose: refused."""
    robot, scene, camera, q = seen
    turned = dataclasses.replace(CAMERA, target=(0.3, 0.55, 0.4))
    bumped = DepthCamera(scene.client, turned, robot).capture()
    lying = dataclasses.replace(bumped, view=camera.view.copy())
    problem = FrameCheck("side", False, LIMITS).check(lying, q, _joints(robot, q))
    assert problem is not None
    assert "does not see the robot where it must" in problem
    # A mounted camera is not held to the joints' places.
    assert FrameCheck("wrist", True, LIMITS).check(lying, q, _joints(robot, q)) is None


def test_an_obstacle_in_front_of_the_arm_is_not_seeing_through(seen) -> None:
    """Occlusion reads nearer than the joints, which is believed."""
    robot, _, camera, q = seen
    frame = camera.capture()
    near = np.full_like(frame.depth, 0.05)  # a wall right in front of the camera
    occluded = dataclasses.replace(frame, depth=near)
    assert (
        FrameCheck("side", False, LIMITS).check(occluded, q, _joints(robot, q)) is None
    )


def test_the_checks_can_be_turned_off() -> None:
    """Limits of 1 refuse nothing for blindness or seeing through."""
    view = np.eye(4)
    view[2, 3] = -2.0
    blind = DepthFrame(np.ones((8, 8)), view, view, 0.1, 3.0)
    off = PlausibilityLimits(max_far_fraction=1.0, see_through_fraction=1.0)
    joints = np.zeros((4, 3))
    assert FrameCheck("c", False, off).check(blind, np.zeros(7), joints) is None


def test_a_camera_on_the_robot_may_look_into_open_space(seen) -> None:
    """Nothing up to the far plane: believed where the map holds nothing in view.

    A wrist camera turned away from the workcell reads nothing, and is right;
    the same frame where the map holds the table in view is a blind sensor.
    """
    robot, _, camera, q = seen
    frame = camera.capture()
    blind = dataclasses.replace(frame, depth=np.ones_like(frame.depth))
    spec = PerceptionSpec(cell_size=0.02, bounds=((-0.2, -0.8, 0.0), (1.2, 0.8, 1.0)))
    empty = OccupancyGrid(spec, None)
    assert empty.occupied_in_view(blind) == 0.0
    wrist = FrameCheck("wrist", mounted=True, limits=LIMITS)
    assert wrist.check(blind, q, _joints(robot, q), empty.occupied_in_view) is None
    mapped = OccupancyGrid(spec, None)
    mapped.integrate(frame, None, 0.0)
    assert mapped.occupied_in_view(blind) > EXPECTED_IN_VIEW
    problem = FrameCheck("wrist", True, LIMITS).check(
        blind, q, _joints(robot, q), mapped.occupied_in_view
    )
    assert problem is not None
    assert "where the map holds obstacles" in problem
    # A fixed camera sees the workcell: reading nothing is never believed.
    fixed = FrameCheck("side", False, LIMITS)
    assert fixed.check(blind, q, _joints(robot, q), empty.occupied_in_view)
