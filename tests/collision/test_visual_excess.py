"""How far a robot looks larger than its collision shapes (the self-filter's reach)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pybullet_data
import pytest
import trimesh

from cbp.collision import RobotGeometry
from cbp.collision.geometry import UNREAD_VISUAL_EXCESS
from cbp.robot import RobotModel

URDF = """<?xml version="1.0"?>
<robot name="two_boxes">
  <link name="base">
    <visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual>
    <collision><geometry><box size="0.08 0.08 0.08"/></geometry></collision>
  </link>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="arm"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="arm">
    <inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual>
      <origin xyz="0 0 0.01"/>
      <geometry>{arm_visual}</geometry>
    </visual>
    <collision><geometry><cylinder radius="0.05" length="0.2"/></geometry></collision>
  </link>
</robot>
"""


def _robot(tmp_path: Path, arm_visual: str) -> RobotModel:
    path = tmp_path / "two_boxes.urdf"
    path.write_text(URDF.format(arm_visual=arm_visual))
    return RobotModel.from_urdf(path)


def test_a_visual_box_larger_than_its_collision_box_reaches_past_it(tmp_path) -> None:
    # base: a 10 cm box drawn around an 8 cm one: 1 cm past every face.
    # arm: a 10 cm cylinder drawn 1 cm higher than its 20 cm collision cylinder.
    robot = _robot(tmp_path, '<cylinder radius="0.05" length="0.2"/>')
    excess = RobotGeometry(robot).visual_excess
    assert excess == pytest.approx([0.01, 0.01], abs=1e-9)


def test_a_visual_inside_its_shapes_reaches_nothing(tmp_path) -> None:
    robot = _robot(tmp_path, '<sphere radius="0.03"/>')
    assert RobotGeometry(robot).visual_excess[1] == 0.0


def test_a_scaled_visual_mesh_counts_at_its_drawn_size(tmp_path) -> None:
    trimesh.creation.box(extents=(0.05, 0.05, 0.1)).export(tmp_path / "arm.stl")
    # Drawn at twice its size: 10 x 10 x 20 cm, 1 cm higher than the cylinder
    # of radius 5 cm (its box corners reach sqrt(2) * 5 - 5 cm past its side).
    robot = _robot(tmp_path, f'<mesh filename="{tmp_path / "arm.stl"}" scale="2 2 2"/>')
    excess = RobotGeometry(robot).visual_excess[1]
    assert excess == pytest.approx(0.05 * (np.sqrt(2) - 1), abs=2e-3)


def test_an_unreadable_visual_mesh_takes_the_old_reach_and_says_so(
    tmp_path, caplog
) -> None:
    (tmp_path / "arm.stl").write_text("not a mesh")
    robot = _robot(tmp_path, f'<mesh filename="{tmp_path / "arm.stl"}"/>')
    with caplog.at_level(logging.WARNING, logger="cbp.collision.geometry"):
        excess = RobotGeometry(robot).visual_excess
    assert list(excess) == [UNREAD_VISUAL_EXCESS] * 2
    assert "cannot read the visual geometry" in caplog.text
    assert "arm.stl" in caplog.text
    assert "30 mm" in caplog.text


def test_shipped_and_pybullet_arms_look_as_large_as_their_shapes(robots) -> None:
    # The Panda's collision meshes stand in for its visual ones; the xArm 6
    # draws detailed meshes around convex decompositions (up to 2 mm beyond).
    assert RobotGeometry(robots["panda"]).visual_excess.max() < 1e-6
    xarm = RobotModel.from_urdf(
        Path(pybullet_data.getDataPath()) / "xarm/xarm6_robot.urdf"
    )
    excess = RobotGeometry(xarm).visual_excess
    assert 0.0005 < excess.max() < 0.005
