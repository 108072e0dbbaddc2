"""A robot of one's own is checked at load: mesh files, joint ranges, its name."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pybullet_data
import pytest
import yaml

import cbp.robot.loading
from cbp.cli import main
from cbp.errors import ConfigError, RobotNotFoundError, ScenarioError
from cbp.robot import LIMIT_TOLERANCE, RobotModel, find_robot_folder
from cbp.scenario import load_scenario
from cbp.sim.scene import PybulletScene
from cbp.urdf_files import mesh_uses, missing_meshes

XARM = Path(pybullet_data.getDataPath()) / "xarm" / "xarm6_robot.urdf"
LINK3 = "xarm_description/meshes/xarm6/visual/link3.stl"

SCENARIO = """\
name: own
include: cat
robot: {name: arm}
duration: 1.0
goal: {type: keyframes, keyframes: [{t: 0.5, pose: {position: [0.35, 0.2, 0.25], rpy_deg: [180, 0, 0]}}]}
world: {objects: [{name: post, shape: cylinder, size: [0.04, 0.3], pose: {position: [0.45, 0.0, 0.15]}}]}
"""

#: A two-joint arm: a prismatic joint in [0, 0.2] m, then a continuous joint.
TOY_URDF = """\
<robot name="toy">
  <link name="base"/>
  <link name="slider">
    <visual><geometry><mesh filename="meshes/slider.stl"/></geometry></visual>
    <collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision>
  </link>
  <link name="wheel">
    <collision>
      <geometry><mesh filename="package://toy/wheel.stl"/></geometry>
    </collision>
  </link>
  <joint name="slide" type="prismatic">
    <parent link="base"/><child link="slider"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.2" effort="1" velocity="1"/>
  </joint>
  <joint name="spin" type="continuous">
    <parent link="slider"/><child link="wheel"/><axis xyz="0 0 1"/>
    <limit effort="1" velocity="1"/>
  </joint>
</robot>
"""


def _xarm(tmp_path: Path) -> Path:
    """``cbp robot init`` of the xArm 6 into ``tmp_path/arm``, with a scenario beside it."""
    command = ["-q", "robot", "init", str(XARM), "--out", str(tmp_path / "arm")]
    assert main([*command, "--samples", "0"]) == 0
    (tmp_path / "s.yaml").write_text(SCENARIO)
    return tmp_path / "arm"


def _without_link3(arm: Path) -> int:
    """Delete the robot folder ``arm``'s visual mesh of link3; its URDF line."""
    (arm / LINK3).unlink()
    return _line_of(arm / "robot.urdf", LINK3)


def _line_of(path: Path, text: str) -> int:
    """The 1-based line of ``path`` holding ``text``."""
    lines = path.read_text().splitlines()
    return next(i for i, line in enumerate(lines, start=1) if text in line)


def test_mesh_uses_name_their_link_element_and_line(tmp_path: Path) -> None:
    """Each <mesh> of a link's visual or collision comes with its link and line."""
    urdf = tmp_path / "robot" / "toy.urdf"
    urdf.parent.mkdir()
    urdf.write_text(TOY_URDF)
    uses = mesh_uses(urdf)
    assert [(u.link, u.element, u.filename, u.line) for u in uses] == [
        ("slider", "visual", "meshes/slider.stl", 4),
        ("wheel", "collision", "package://toy/wheel.stl", 9),
    ]
    assert missing_meshes(urdf) == uses
    (urdf.parent / "meshes").mkdir()
    (urdf.parent / "meshes" / "slider.stl").write_text("solid")
    assert missing_meshes(urdf) == uses[1:]
    (tmp_path / "toy").mkdir()  # a ROS tree: the package beside the URDF's folder
    (tmp_path / "toy" / "wheel.stl").write_text("solid")
    assert missing_meshes(urdf) == []


def test_package_meshes_are_found_where_ros_looks(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A package:// mesh under ROS_PACKAGE_PATH or an ament prefix's share is found."""
    urdf = tmp_path / "robot" / "toy.urdf"
    urdf.parent.mkdir()
    urdf.write_text(TOY_URDF.replace("meshes/slider.stl", "package://toy/slider.stl"))
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    assert len(missing_meshes(urdf)) == 2
    ros1 = tmp_path / "ros1" / "toy"
    ros1.mkdir(parents=True)
    (ros1 / "slider.stl").write_text("solid")
    monkeypatch.setenv("ROS_PACKAGE_PATH", f"/nowhere{os.pathsep}{ros1.parent}")
    assert [u.filename for u in missing_meshes(urdf)] == ["package://toy/wheel.stl"]
    ros2 = tmp_path / "install" / "share" / "toy"
    ros2.mkdir(parents=True)
    (ros2 / "wheel.stl").write_text("solid")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "install"))
    assert missing_meshes(urdf) == []


def test_check_and_run_refuse_a_missing_visual_mesh_at_its_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`cbp check` and `cbp run` exit 2 naming robot.yaml, the URDF's line, the link and the file."""
    arm = _xarm(tmp_path)
    line = _without_link3(arm)
    urdf_line = _line_of(arm / "robot.yaml", "urdf: robot.urdf")
    expected = (
        f"  {arm / 'robot.yaml'}, line {urdf_line}: urdf: robot.urdf, line {line}: "
        f"link 'link3': cannot find its visual mesh '{LINK3}'\n"
    )
    capsys.readouterr()
    assert main(["-q", "check", str(tmp_path / "s.yaml")]) == 2
    assert capsys.readouterr().err == f"{tmp_path / 's.yaml'}: 1 problem:\n{expected}"
    out = tmp_path / "out"
    assert main(["-q", "run", str(tmp_path / "s.yaml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert expected in err
    assert "Traceback" not in err
    assert not out.exists()


def test_robot_init_refuses_a_urdf_with_a_missing_mesh(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`cbp robot init` on a URDF missing a visual mesh exits 2 at its line, writing nothing."""
    arm = _xarm(tmp_path)
    line = _without_link3(arm)
    capsys.readouterr()
    command = ["robot", "init", str(arm / "robot.urdf"), "--out", str(tmp_path / "b")]
    assert main(["-q", *command, "--samples", "0"]) == 2
    assert capsys.readouterr().err == (
        f"{arm / 'robot.urdf'}: 1 problem:\n"
        f"  line {line}: link 'link3': cannot find its visual mesh '{LINK3}'\n"
    )
    assert not (tmp_path / "b").exists()


def test_a_urdf_pybullet_refuses_is_a_located_error(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """PyBullet's failure to load the robot is a ConfigError naming the URDF and why."""
    arm = _xarm(tmp_path)
    robot = RobotModel.load(str(arm))
    line = _without_link3(arm)
    with pytest.raises(ConfigError) as info:
        PybulletScene(robot, [])
    assert str(info.value) == (
        f"{arm / 'robot.urdf'}: PyBullet cannot load robot 'xarm6' (line {line}: "
        f"link 'link3': cannot find its visual mesh '{LINK3}')"
    )
    # Past the load-time check (as if the file went missing after it), `cbp
    # run` says the same and exits 2 rather than show PyBullet's traceback.
    monkeypatch.setattr(cbp.robot.loading, "missing_meshes", lambda *args: [])
    capsys.readouterr()
    out = tmp_path / "out"
    command = ["-q", "run", str(tmp_path / "s.yaml"), "--out", str(out)]
    assert main([*command, "--method", "ik"]) == 2
    err = capsys.readouterr().err
    assert "PyBullet cannot load robot 'xarm6'" in err
    assert "Traceback" not in err
    assert not out.exists()


def test_robot_init_refuses_a_home_outside_the_joint_range(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`--home joint2=5.0` is refused naming the joint, the value and its range."""
    command = ["-q", "robot", "init", str(XARM), "--out", str(tmp_path / "arm")]
    assert main([*command, "--samples", "0", "--home", "joint2=5.0"]) == 2
    assert capsys.readouterr().err == (
        "home.joint2: joint 'joint2' at 5 rad is outside its range "
        "[-2.059, 2.094] rad (xarm6_robot.urdf)\n"
    )
    assert not (tmp_path / "arm" / "robot.yaml").exists()


@pytest.mark.parametrize(
    ("key", "value", "shown"),
    [("robot.initial.joint2", "5.0", "5"), ("robot.initial", "{joint2: -3.0}", "-3")],
)
def test_an_initial_position_outside_the_range_is_located(
    tmp_path: Path, key: str, value: str, shown: str
) -> None:
    """robot.initial beyond a limit, from --set or in the file, names joint, value and range."""
    _xarm(tmp_path)
    with pytest.raises(ScenarioError) as info:
        load_scenario(tmp_path / "s.yaml", overrides={key: value})
    (problem,) = info.value.problems
    assert problem.endswith(
        f"robot.initial.joint2: joint 'joint2' at {shown} rad is outside its range "
        "[-2.059, 2.094] rad (robot.urdf)"
    )
    text = SCENARIO.replace("{name: arm}", "{name: arm, initial: {joint2: 5.0}}")
    (tmp_path / "s.yaml").write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(tmp_path / "s.yaml")
    assert info.value.problems == [
        "line 3: robot.initial.joint2: joint 'joint2' at 5 rad is outside its "
        "range [-2.059, 2.094] rad (robot.urdf)"
    ]


def test_a_position_at_a_limit_passes(tmp_path: Path) -> None:
    """A value at a limit, or rounded just past it, is within the range."""
    arm = _xarm(tmp_path)
    robot = RobotModel.load(str(arm))
    lower, upper, unit = robot.joint_range("joint2") or (0.0, 0.0, "")
    assert unit == "rad"
    for value in (lower, upper, upper + 0.5 * LIMIT_TOLERANCE):
        load_scenario(
            tmp_path / "s.yaml", overrides={"robot.initial.joint2": repr(value)}
        )
    assert robot.out_of_range("joint2", upper + 2 * LIMIT_TOLERANCE)


def test_prismatic_ranges_are_in_metres_and_continuous_joints_have_none(
    tmp_path: Path,
) -> None:
    """A prismatic joint's range is in m; a continuous joint takes any angle."""
    (tmp_path / "toy.urdf").write_text(TOY_URDF)
    robot = RobotModel.from_urdf(tmp_path / "toy.urdf")
    assert robot.joint_range("slide") == (0.0, 0.2, "m")
    assert robot.out_of_range("slide", 0.3) == (
        "joint 'slide' at 0.3 m is outside its range [0, 0.2] m (toy.urdf)"
    )
    assert robot.joint_range("spin") is None
    assert robot.out_of_range("spin", 100.0) is None


def test_a_continuous_joint_is_placed_by_its_angle(tmp_path: Path) -> None:
    """A position for a continuous joint is written as (cos, sin), also when locked."""
    (tmp_path / "toy.urdf").write_text(TOY_URDF)
    robot = RobotModel.from_urdf(tmp_path / "toy.urdf")
    q = robot.neutral()
    robot.set_joint_position(q, "spin", 2.5)
    robot.set_joint_position(q, "slide", 0.1)
    np.testing.assert_allclose(q, [0.1, np.cos(2.5), np.sin(2.5)])
    assert robot.joint_position(q, "spin") == pytest.approx(2.5)
    assert robot.joint_position(q, "slide") == pytest.approx(0.1)
    locked = RobotModel.from_urdf(tmp_path / "toy.urdf", locked_joints={"spin": 2.5})
    wheel = locked.model.frames[locked.model.getFrameId("wheel")].placement
    angle = np.arctan2(wheel.rotation[1, 0], wheel.rotation[0, 0])
    assert angle == pytest.approx(2.5)


def test_robot_yaml_problems_are_reported_together(tmp_path: Path) -> None:
    """A key typo, a bad end effector and a home out of range: all three at once."""
    arm = _xarm(tmp_path)
    path = arm / "robot.yaml"
    document = yaml.safe_load(path.read_text())
    document["end_effector"] = "link7"
    document["home"]["joint2"] = 5.0
    document["acceleration_limit"] = document.pop("acceleration_limits")
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    with pytest.raises(ScenarioError) as info:
        load_scenario(tmp_path / "s.yaml")
    lines = {
        key: _line_of(path, key)
        for key in ("acceleration_limit:", "end_effector:", "  joint2:")
    }
    assert sorted(info.value.problems) == sorted(
        [
            # An unknown key is located at its own line.
            f"{path}, line {lines['acceleration_limit:']}: acceleration_limit: "
            "unknown key 'acceleration_limit'; did you mean 'acceleration_limits'? "
            "Accepted: name, urdf, end_effector, home, base, wrist_link, "
            "locked_joints, velocity_limits, acceleration_limits, collision.",
            f"{path}, line {lines['end_effector:']}: end_effector: no frame 'link7' "
            "in robot.urdf; close matches: link6, link5, link4",
            f"{path}, line {lines['  joint2:']}: home.joint2: joint 'joint2' at 5 "
            "rad is outside its range [-2.059, 2.094] rad (robot.urdf)",
        ]
    )


def test_robot_not_found_says_where_it_looked_and_suggests_local_folders(
    tmp_path: Path,
) -> None:
    """A misspelt robot folder beside the scenario is suggested; the folders searched are named."""
    (tmp_path / "my_xarm").mkdir()
    (tmp_path / "my_xarm" / "robot.yaml").write_text("name: x\n")
    with pytest.raises(RobotNotFoundError) as info:
        find_robot_folder("my_xram", tmp_path)
    message = str(info.value)
    assert message.startswith(
        f"no robot 'my_xram': no folder 'my_xram' with a robot.yaml in {tmp_path} "
        f"(beside the scenario), "
    )
    assert f"{cbp.robot.ROBOTS_DIR} (shipped robots). Did you mean 'my_xarm'? " in (
        message
    )
    assert message.endswith("Robots on the search path: franka_panda, kuka_youbot.")
    with pytest.raises(RobotNotFoundError, match=f"Did you mean '{tmp_path}/my_xarm'"):
        find_robot_folder(str(tmp_path / "my_xram"), tmp_path)
