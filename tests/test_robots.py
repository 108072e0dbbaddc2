"""Every robot folder loads in pinocchio and PyBullet and is consistent."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pybullet as pb
import pytest

from cbp.robot import ROBOTS_DIR, RobotModel

FOLDERS = sorted(p.parent.name for p in ROBOTS_DIR.glob("*/robot.yaml"))


@pytest.mark.parametrize("name", FOLDERS)
def test_robot_folder(name: str) -> None:
    """URDF loads in both; names in robot.yaml exist; home within limits; licence."""
    robot = RobotModel.load(name)
    folder = ROBOTS_DIR / name
    assert (folder / "LICENSE").is_file()
    assert robot.description is not None
    robot.frame_id(robot.description.end_effector)
    home = robot.home()
    bq = robot.bounded_q
    assert np.all(home[bq] >= robot.lower_limits[bq])
    assert np.all(home[bq] <= robot.upper_limits[bq])
    client = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(
            str(Path(robot.urdf_path)), useFixedBase=True, physicsClientId=client
        )
        assert pb.getNumJoints(body, physicsClientId=client) > 0
    finally:
        pb.disconnect(client)
