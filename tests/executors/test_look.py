"""Planners that see: the camera on the arm turned to an unseen goal, and MP's reach."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from cbp.collision.geometry import WorldShapes
from cbp.errors import ConfigError, ScenarioError
from cbp.executors import load_executor
from cbp.executors.aiming import looking_at, solve_camera
from cbp.executors.visibility import UNSEEN_DEPTH, CellStates, in_view, visibility
from cbp.methods.settings import LookSettings
from cbp.metrics import run_metrics
from cbp.perception.kernels import FREE, OCCUPIED, UNKNOWN
from cbp.perception.spec import CameraSpec
from cbp.robot import RobotModel
from cbp.run.budget import VirtualBudget, VirtualCosts
from cbp.scenario import load_scenario
from tests.conftest import VIRTUAL_CLOCK

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
CAMERAS = {"perception.source": "depth_camera", **VIRTUAL_CLOCK}


def test_a_camera_sees_points_in_its_view_not_behind_an_occupied_cell() -> None:
    """In the field of view and range and with a clear line: seen; else not."""
    # Optical frame: +z along the axis, here the world's +x.
    camera = pin.SE3(np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]]), np.zeros(3))
    spec = CameraSpec(name="c", position=(0, 0, 0), target=(1, 0, 0), fov_deg=60.0)
    cell = 0.01
    # Free cells from the camera to x = 1.1, one occupied at (0.5, 0.3, 0).
    cells = np.full((111, 70, 1), FREE, dtype=np.uint8)
    cells[50, 30, 0] = OCCUPIED
    grid = CellStates(cells, np.array([-0.005, -0.005, -0.005]), cell)

    points = np.array(
        [
            [1.0, 0.0, 0.0],  # ahead
            [1.0, 0.6, 0.0],  # ahead, behind the occupied cell
            [-1.0, 0.0, 0.0],  # behind the camera
            [1.0, 0.0, 2.0],  # out of the field of view
            [0.05, 0.0, 0.0],  # nearer than the camera's range
            [0.5, 0.3, 0.0],  # the occupied cell itself is seen
        ]
    )
    got = visibility(camera, spec, points, grid)
    np.testing.assert_array_equal(got, [1.0, 0.0, 0.0, 0.0, 0.0, 1.0])


def test_unseen_space_on_the_line_makes_a_point_less_likely_seen() -> None:
    """Each UNSEEN_DEPTH of unseen space before a point: a factor e less; the robot hides.

    Space outside the grid is unseen as well.
    """
    camera = pin.SE3(np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]]), np.zeros(3))
    spec = CameraSpec(name="c", position=(0, 0, 0), target=(1, 0, 0), fov_deg=60.0)
    cell = 0.01
    # Free from x = -0.1 to 0.5, unseen from there to the grid's end at 0.8.
    cells = np.full((90, 20, 20), UNKNOWN, dtype=np.uint8)
    cells[:60] = FREE
    grid = CellStates(cells, np.array([-0.1, -0.1, -0.1]), cell)

    points = np.array([[0.505, 0.0, 0.0], [0.6, 0.0, 0.0], [0.7, 0.0, 0.0]])
    got = visibility(camera, spec, points, grid)
    assert got[0] == 1.0  # on the frontier
    depth = points[1:, 0] - 0.5 - 1.5 * cell  # the unseen length before each
    np.testing.assert_allclose(got[1:], np.exp(-depth / UNSEEN_DEPTH), rtol=0.1)
    # Outside the grid is unseen too: beyond its end as beyond x = 0.5.
    far = visibility(camera, spec, np.array([[0.9, 0.0, 0.0]]), grid)
    depth = 0.9 - 0.5 - 1.5 * cell
    np.testing.assert_allclose(far, np.exp(-depth / UNSEEN_DEPTH), rtol=0.1)

    # A link across the line at x = 0.3: a slab 4 cm thick.
    slab = WorldShapes(
        np.array(
            [
                [1.0, 0, 0, 0.32],
                [-1, 0, 0, -0.28],
                [0, 1, 0, 1],
                [0, -1, 0, 1],
                [0, 0, 1, 1],
                [0, 0, -1, 1],
            ]
        ),
        np.array([0, 6]),
        np.array([[0.3, 0.0, 0.0]]),
        np.array([1.42]),
        np.zeros((1, 4, 4)),
    )
    hidden = visibility(camera, spec, points, grid, slab)
    np.testing.assert_array_equal(hidden, 0.0)
    beside = visibility(camera, spec, points, grid, slab, grow=-0.03)
    assert np.all(beside > 0.0)  # shrunk to nothing, the slab hides nothing


def _visibility_by_numpy(camera, spec, points, grid, body):  # type: ignore[no-untyped-def]
    """The prediction as first written, in numpy: every line sampled whole."""
    inside = in_view(camera, spec, points)  # the field of view as the library's
    out = np.zeros(len(points))
    eye = camera.translation
    d = points[inside] - eye
    length = np.linalg.norm(d, axis=1)
    k = max(2, int(np.max(length) / (0.5 * grid.cell)))
    ts = np.linspace(0.0, 1.0, k)
    along = eye + ts[None, :, None] * d[:, None, :]
    at = ts[None, :] * length[:, None]
    before = at < length[:, None] - 1.5 * grid.cell
    idx = np.floor((along.reshape(-1, 3) - grid.lower) / grid.cell).astype(int)
    ok = np.all((idx >= 0) & (idx < grid.cells.shape), axis=1)
    state = np.full(len(idx), UNKNOWN, dtype=np.uint8)  # outside: unseen
    state[ok] = grid.cells[idx[ok, 0], idx[ok, 1], idx[ok, 2]]
    state = state.reshape(len(d), k)
    blocked = np.any((state == OCCUPIED) & before, axis=1)
    asked = before & (at > spec.near) & ~blocked[:, None]
    flat = along[asked]
    hit = np.zeros_like(asked)
    hit[asked] = np.all(flat @ body.planes[:, :3].T - body.planes[:, 3] <= 0.0, axis=1)
    blocked |= np.any(hit, axis=1)
    unseen = np.count_nonzero((state == UNKNOWN) & before, axis=1) * length / (k - 1)
    out[inside] = np.where(blocked, 0.0, np.exp(-unseen / UNSEEN_DEPTH))
    return out


def test_the_compiled_lines_of_sight_agree_with_sampling_every_line_whole() -> None:
    """A random map, a box of the robot in the way: the same chances as numpy's."""
    rng = np.random.default_rng(7)
    cells = rng.choice(
        np.array([FREE, UNKNOWN, OCCUPIED], dtype=np.uint8),
        size=(60, 60, 60),
        p=[0.9, 0.095, 0.005],
    )
    grid = CellStates(cells, np.array([0.2, -0.3, -0.3]), 0.01)
    camera = pin.SE3(np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]]), np.zeros(3))
    spec = CameraSpec(name="c", position=(0, 0, 0), target=(1, 0, 0), fov_deg=60.0)
    box = WorldShapes(
        np.array(
            [
                [1.0, 0, 0, 0.45],
                [-1, 0, 0, -0.35],
                [0, 1, 0, 0.05],
                [0, -1, 0, 0.05],
                [0, 0, 1, 0.05],
                [0, 0, -1, 0.05],
            ]
        ),
        np.array([0, 6]),
        np.array([[0.4, 0.0, 0.0]]),
        np.array([0.09]),
        np.zeros((1, 4, 4)),
    )
    points = rng.uniform([0.2, -0.3, -0.3], [0.8, 0.3, 0.3], (400, 3))
    got = visibility(camera, spec, points, grid, box)
    want = _visibility_by_numpy(camera, spec, points, grid, box)
    np.testing.assert_allclose(got, want, atol=1e-12)
    assert 0 < np.count_nonzero(got == 0.0) < len(points)  # some hidden, some not
    assert np.count_nonzero((got > 0.0) & (got < 1.0)) > 0  # some behind unseen


def test_the_arm_is_solved_for_a_camera_pose_aimed_at_a_point(
    robots: dict[str, RobotModel],
) -> None:
    """A pose looking at a point from a reachable eye: the camera's axis meets the point."""
    robot = robots["panda"]
    frame = robot.frame_id("panda_hand")
    offset = pin.SE3(
        pin.rpy.rpyToMatrix(0.0, np.deg2rad(25.0), 0.0), np.array([0.06, 0, 0.03])
    )
    q = np.array([-0.32, 0.09, -0.19, -2.33, 0.03, 2.42, -1.31])
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    here = data.oMf[frame] * offset
    centre = np.array([0.45, 0.25, 0.3])
    pose = looking_at(
        here.translation + np.array([0.0, 0.05, 0.1]), centre, here.rotation
    )
    axis = (centre - pose.translation) / np.linalg.norm(centre - pose.translation)
    np.testing.assert_allclose(pose.rotation[:, 2], axis, atol=1e-12)
    # Rolled as near the old pose as the new axis allows: x in the plane of
    # the old x and the new axis, on the old x's side.
    x, old_x = pose.rotation[:, 0], here.rotation[:, 0]
    assert abs(np.linalg.det(np.column_stack([x, old_x, axis]))) < 1e-12
    assert np.dot(x, old_x) > 0.0
    budget = VirtualBudget(10.0, VirtualCosts())
    solved = solve_camera(robot, frame, offset, pose, q, budget)
    assert solved is not None
    pin.framesForwardKinematics(robot.model, data, solved)
    there = data.oMf[frame] * offset
    assert np.linalg.norm(there.translation - pose.translation) < 0.01
    assert np.dot(there.rotation[:, 2], axis) > np.cos(0.05)
    assert budget.elapsed() > 0.0


def test_look_settings_are_checked() -> None:
    """A share outside (0, 1] or a look count of 0 is refused, naming the key."""
    with pytest.raises(ConfigError) as info:
        LookSettings(unseen_share=0.0)
    assert info.value.location == "unseen_share"
    with pytest.raises(ScenarioError, match="looks"):
        load_scenario(
            SCENARIOS / "cat_boards.yaml",
            overrides={"method.name": "mp", "method.mp.look.looks": "0"},
        )


@pytest.mark.slow
def test_mp_says_the_goal_is_unseen_and_turns_the_wrist_camera_to_it() -> None:
    """Behind the wall with the cameras: an event names the unseen goal, the arm looks."""
    scenario = load_scenario(
        SCENARIOS / "cat_local_minimum.yaml",
        overrides={"method.name": "mp", "duration": "2.5", **CAMERAS},
    )
    trace = load_executor("mp")(scenario, False)
    m = run_metrics(trace, scenario.robot)
    events = "\n".join(message for _, message in trace.events)
    assert "mp: the goal lies in space no camera has seen" in events
    assert "turning camera 'wrist' to look before planning" in events
    assert "moving there to look" in events
    assert m["looks"] >= 1
    assert m["peak_contact_force_n"] == 0.0


@pytest.mark.slow
def test_mp_with_the_cameras_reaches_the_wrist_limit_goal() -> None:
    """On the virtual clock MP keeps its own 4 Hz period and reaches, without contact."""
    scenario = load_scenario(
        SCENARIOS / "cat_wrist_limit.yaml", overrides={"method.name": "mp", **CAMERAS}
    )
    assert scenario.spec.method.timing("mp").period == 0.25
    trace = load_executor("mp")(scenario, False)
    m = run_metrics(trace, scenario.robot)
    assert m["reached"], m["final_position_error_m"]
    assert m["peak_contact_force_n"] == 0.0


@pytest.mark.slow
def test_mp_looks_behind_the_wall_then_plans_over_it_with_the_cameras() -> None:
    """MP's search goes on over the map's snapshots and its random starts find the goal.

    On the virtual clock: six looks, the goal's configuration found at 7.5 s
    and reached at 10.4 s. Before, every search began anew with each snapshot
    and the redundant joint's sweep from the last view found no solution:
    after five looks the arm held for good.
    """
    scenario = load_scenario(
        SCENARIOS / "cat_local_minimum.yaml",
        overrides={"method.name": "mp", "duration": "12", **CAMERAS},
    )
    trace = load_executor("mp")(scenario, False)
    m = run_metrics(trace, scenario.robot)
    events = "\n".join(message for _, message in trace.events)
    assert "mp: camera 'wrist' sees" in events
    assert "mp: a collision-free IK solution found" in events
    assert m["plans"] >= 1
    assert m["reached"], m["final_position_error_m"]
    assert m["peak_contact_force_n"] == 0.0


@pytest.mark.slow
def test_the_hybrid_escapes_the_local_minimum_with_the_cameras() -> None:
    """CAT stalls before the wall; the hybrid looks until it sees a way, plans, reaches.

    The run is 20 s long, with a map check charged as it costs (60 us): the
    stall takes about 2 s, then ten looks and the plan over the wall reach at
    15.4 s; the scene's own 8 s ends while the hybrid is still looking.
    """
    scenario = load_scenario(
        SCENARIOS / "cat_local_minimum.yaml",
        overrides={"method.name": "hybrid", "duration": "20", **CAMERAS},
    )
    trace = load_executor("hybrid")(scenario, False)
    m = run_metrics(trace, scenario.robot)
    events = "\n".join(message for _, message in trace.events)
    assert "hybrid: the goal lies in space no camera has seen" in events
    assert "hybrid: camera 'wrist' sees" in events
    assert m["looks"] >= 1
    assert m["plans"] == 1
    assert m["reached"], m["final_position_error_m"]
    assert m["peak_contact_force_n"] == 0.0
