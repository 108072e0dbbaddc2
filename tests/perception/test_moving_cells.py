"""What moves is measured ahead while it could move; what another camera sees is free."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from cbp.collision import RobotGeometry
from cbp.perception.kernels import FREE, UNKNOWN
from cbp.perception.moving import GROWTH_STEP, moving_growth
from cbp.perception.occupancy import OccupancyGrid
from cbp.sim.camera import DepthCamera
from cbp.sim.scene import PybulletScene
from cbp.state import RobotState
from tests.collision.test_map_states import BEHIND, BOX, FRONT, SIDE, SPEC


def test_the_growth_shrinks_once_nothing_is_entered() -> None:
    """Full while cells are entered; the speed a cell per still-time after; a floor."""
    speed, ahead, cell, frame = 0.25, 0.6, 0.01, 1.0 / 15.0
    moving = moving_growth(speed, ahead, 0.0, 0.0, cell, frame)
    assert moving == pytest.approx(0.15)  # 25 cm/s over 0.6 s, as before
    assert moving_growth(speed, ahead, 0.0) == moving
    still = [moving_growth(speed, ahead, 0.0, s, cell, frame) for s in (0.1, 0.3, 1.0)]
    assert still == pytest.approx([0.06, 0.02, 0.02])  # 10 cm/s, 3.3 cm/s, floor
    floor = speed * frame
    assert still[-1] == pytest.approx(np.ceil(floor / GROWTH_STEP) * GROWTH_STEP)
    # The snapshot's age is counted at the assumed speed: it may have started.
    assert moving_growth(speed, ahead, 0.2, 1.0, cell, frame) == pytest.approx(0.07)


@pytest.fixture(scope="module")
def frames(robots):  # type: ignore[no-untyped-def]
    """FRONT's and SIDE's frames without the box, then with it; the robot at home."""
    robot = robots["panda"]
    out = {}
    with PybulletScene(robot, []) as empty:
        empty.set_configuration(robot.home())
        out["front_empty"] = DepthCamera(empty.client, FRONT).capture()
        out["side_empty"] = DepthCamera(empty.client, SIDE).capture()
    with PybulletScene(robot, [BOX]) as scene:
        scene.set_configuration(robot.home())
        out["front"] = DepthCamera(scene.client, FRONT).capture()
        out["side"] = DepthCamera(scene.client, SIDE).capture()
    return out


def test_a_surface_that_stands_still_is_not_entered_again(frames, robots) -> None:  # type: ignore[no-untyped-def]
    """The box's face comes once; its cells, occupied since, are not entered anew."""
    robot = robots["panda"]
    grid = OccupancyGrid(replace(SPEC, shadow_hold=5.0), RobotGeometry(robot))
    state = RobotState(robot, robot.home())
    grid.integrate(frames["front_empty"], state, 0.0)
    grid.integrate(frames["front"], state, 0.1)  # the box came between
    centres, newest = grid.moving(0.1)
    assert len(centres) > 20
    assert newest == pytest.approx(0.1)
    for t in (0.2, 0.3):  # the same reading: its cells stay occupied
        grid.integrate(frames["front"], state, t)
    centres, newest = grid.moving(0.3)
    assert len(centres) > 20
    assert newest == pytest.approx(0.1)  # nothing entered since it came


def test_a_cell_one_camera_sees_through_is_free_whatever_another_hides(
    frames, robots
) -> None:  # type: ignore[no-untyped-def]
    """Behind the box from FRONT, seen through by SIDE at the same instant: free.

    Frame by frame, FRONT's frame after SIDE's made it unknown again.
    """
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    state = RobotState(robot, robot.home())
    outcome = {}
    for together in (False, True):
        grid = OccupancyGrid(SPEC, geometry)
        grid.integrate_together(
            [(frames["front_empty"], state, 0.0), (frames["side_empty"], state, 0.0)]
        )
        assert grid.state_at(BEHIND)[0] == FREE
        now = [(frames["side"], state, 0.1), (frames["front"], state, 0.1)]
        if together:
            summaries = grid.integrate_together(now)
        else:
            summaries = [grid.integrate(*frame) for frame in now]
        assert summaries[1].hidden > 0  # FRONT's reading came nearer: it hides
        outcome[together] = int(grid.state_at(BEHIND)[0])
    assert outcome == {False: UNKNOWN, True: FREE}
