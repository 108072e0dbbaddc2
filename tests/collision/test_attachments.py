"""Bodies on the robot beyond its URDF: a mounted camera's housing is a robot shape."""

from __future__ import annotations

from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest

from cbp.collision import RobotGeometry
from cbp.collision.geometry import Attachment
from cbp.collision.objects import EnvironmentObject, PrimitiveEnvironment
from cbp.errors import ConfigError
from cbp.perception.spec import CameraSpec
from cbp.scenario import load_scenario
from cbp.state import RobotState

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _scenario(source: str):
    return load_scenario(
        SCENARIOS / "cat_free_step.yaml", overrides={"perception.source": source}
    )


def _wrist(scenario) -> CameraSpec:
    return next(c for c in scenario.spec.perception.all_cameras if c.name == "wrist")


def test_the_wrist_camera_housing_joins_the_robot_while_cameras_are_used() -> None:
    with_cameras = _scenario("depth_camera").world_for_run().geometry
    declared = _scenario("ground_truth").world_for_run().geometry
    names = [s.name for s in with_cameras.shapes]
    assert names[-1] == "camera_wrist"
    assert "camera_wrist" not in [s.name for s in declared.shapes]
    housing = with_cameras.shapes[-1]
    assert housing.link == "panda_hand"
    # Its front face holds the optical centre; it lies behind it.
    spec = _wrist(_scenario("depth_camera"))
    optical = spec.offset.to_se3()
    behind = optical.act(np.array([0.0, 0.0, -0.01]))
    ahead = optical.act(np.array([0.0, 0.0, 0.01]))
    assert np.all(housing.planes[:, :3].dot(behind) <= housing.planes[:, 3] + 1e-9)
    assert np.any(housing.planes[:, :3].dot(ahead) > housing.planes[:, 3])


def test_an_obstacle_at_the_camera_is_a_contact_of_its_housing() -> None:
    """An obstacle at the optical centre is nearer the housing than any link."""
    scenario = _scenario("depth_camera")
    world = scenario.world_for_run()
    state = RobotState(scenario.robot, scenario.q0)
    spec = _wrist(scenario)
    hand = state.data.oMf[scenario.robot.frame_id("panda_hand")]
    lens = (hand * spec.offset.to_se3()).translation
    probe = EnvironmentObject.primitive(
        "probe", "sphere", (0.005,), pin.SE3(np.eye(3), lens)
    )
    world.set_environment(PrimitiveEnvironment([probe]))
    contacts = world.contacts(state).environment_part()
    names = [world.geometry.shapes[i].name for i in contacts.shape]
    deepest = names[int(np.argmin(contacts.distance))]
    assert deepest == "camera_wrist"


def test_an_attachment_on_an_unknown_frame_is_refused(robots) -> None:
    box = Attachment("cam", "panda_hnad", pin.SE3.Identity(), coal.Box(0.1, 0.1, 0.1))
    with pytest.raises(ConfigError, match="panda_hand"):
        RobotGeometry(robots["panda"], attachments=[box])
