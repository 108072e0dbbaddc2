"""Scenario files: every problem reported at once, located, with suggestions."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cbp.errors import ScenarioError
from cbp.scenario import load_scenario

SCENARIOS = sorted((Path(__file__).resolve().parents[2] / "scenarios").glob("*.yaml"))

HEADER = """\
name: t
robot: {name: franka_panda}
duration: 1.0
"""


def _load(tmp_path: Path, body: str) -> ScenarioError:
    path = tmp_path / "s.yaml"
    path.write_text(HEADER + textwrap.dedent(body))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert str(path) in str(info.value)
    return info.value


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_shipped_scenarios_validate(path: Path) -> None:
    """Every scenario in scenarios/ loads."""
    load_scenario(path)


def test_unknown_plugin(tmp_path: Path) -> None:
    """Unknown type: location, line, nearest name and the list."""
    error = _load(tmp_path, "tasks:\n  - type: postur\n")
    assert error.problems == [
        "line 5: tasks[0].type: unknown task type 'postur'; did you mean 'posture'? "
        "Available: camera_velocity, goal_pose, joint_step, posture (or a 'module:Class' path)."
    ]


def test_unknown_parameter(tmp_path: Path) -> None:
    """Unknown params key names the accepted ones."""
    error = _load(
        tmp_path, "constraints:\n  - type: joint_limits\n    params: {marginn: 0.1}\n"
    )
    assert error.problems == [
        "line 6: constraints[0].params.marginn: unknown key 'marginn'; did you mean "
        "'margin'? Accepted: margin, joints."
    ]


def test_bad_frame_name(tmp_path: Path) -> None:
    """A frame that does not exist lists close matches, at the params key."""
    error = _load(
        tmp_path,
        "tasks:\n  - type: goal_pose\n    name: ee\n    params:\n      frame: panda_hnd\n",
    )
    assert error.problems == [
        "line 8: tasks[0].params.frame: tasks[0] 'ee' (goal_pose): no frame "
        "'panda_hnd' in robot 'franka_panda'; close matches: panda_hand, "
        "panda_hand_joint, panda_link8"
    ]


def test_wrong_weight_length(tmp_path: Path) -> None:
    """Weight length is checked against the plugin's dimension."""
    error = _load(
        tmp_path,
        "tasks:\n  - type: goal_pose\n    name: ee\n    weight: [1, 1, 1, 1]\n"
        "    params: {frame: panda_hand}\n",
    )
    assert error.problems == [
        "line 7: tasks[0].weight: tasks[0] 'ee' (goal_pose): weight has 4 entries, "
        "expected 1 or 6 (dim of goal_pose)"
    ]


def test_malformed_yaml(tmp_path: Path) -> None:
    """A syntax error names the file and line."""
    error = _load(tmp_path, "tasks: [\n")
    assert len(error.problems) == 1
    assert error.problems[0].startswith("line 5: malformed YAML")


def test_all_problems_together(tmp_path: Path) -> None:
    """Problems in several sections come out in one error, in file order."""
    error = _load(
        tmp_path,
        """\
        method: {name: kinematc}
        tasks:
          - type: posture
            wieght: 1.0
        constraints:
          - type: joint_limits
            params: {margin: yes}
        """,
    )
    assert [p.split(": ")[1] for p in error.problems] == [
        "method.name",
        "tasks[0].wieght",
        "constraints[0].params.margin",
    ]
    assert "did you mean 'kinematic'" in error.problems[0]
    assert "expected a number, got bool True" in error.problems[2]


def test_missing_and_unknown_top_level_keys(tmp_path: Path) -> None:
    """A missing required key and a misspelt one are both reported."""
    path = tmp_path / "s.yaml"
    path.write_text("name: t\nrobot: {name: franka_panda}\ndurration: 1.0\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    text = str(info.value)
    assert "durration: unknown key 'durration'; did you mean 'duration'?" in text
    assert "duration: missing required key 'duration' (a number)" in text


def test_cbp_check_exit_codes(tmp_path: Path) -> None:
    """Cbp check: 0 for a good file, 2 with the errors on stderr for a bad one."""
    bad = tmp_path / "bad.yaml"
    bad.write_text(HEADER + "tasks:\n  - type: postur\n")
    good = subprocess.run(
        [sys.executable, "-m", "cbp", "check", str(SCENARIOS[0])],
        capture_output=True,
        text=True,
    )
    assert good.returncode == 0, good.stderr
    result = subprocess.run(
        [sys.executable, "-m", "cbp", "check", str(bad)], capture_output=True, text=True
    )
    assert result.returncode == 2
    assert "did you mean 'posture'" in result.stderr


def test_a_start_inside_a_declared_object_is_refused(tmp_path) -> None:
    """The error names the link, the object and the depth, at robot.initial."""
    from cbp.state import RobotState

    text = """
name: start_inside
include: {configs}/cat.yaml
robot:
  name: franka_panda
  initial: {{panda_joint1: 0.0}}
duration: 1.0
world:
  objects:
    - {{name: block, shape: box, size: [0.1, 0.1, 0.1], pose: {{position: [{x}, 0.0, {z}]}}}}
"""
    configs = Path(__file__).resolve().parents[2] / "scenarios" / "configs"
    # Put the block 5 mm into the hand: the hand's lowest point at home, less 5 mm.
    probe = tmp_path / "probe.yaml"
    probe.write_text(text.format(configs=configs, x=2.0, z=2.0))
    scenario = load_scenario(probe)
    state = RobotState(scenario.robot, scenario.q0)
    hand = state.data.oMf[scenario.robot.frame_id("panda_hand")].translation
    path = tmp_path / "inside.yaml"
    path.write_text(text.format(configs=configs, x=hand[0], z=hand[2]))
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    message = str(info.value)
    assert "robot.initial" in message
    assert "'block'" in message
    assert "mm deep" in message
    allowed = text.format(configs=configs, x=hand[0], z=hand[2]).replace(
        "  initial:", "  allow_initial_contact: true\n  initial:"
    )
    path.write_text(allowed)
    # The hand in the block's middle: deeper than backing out leaves, refused
    # even when allowed (a shallow allowed start loads: test_start_in_contact).
    with pytest.raises(ScenarioError, match="deeper than the 40 mm an arm backs out"):
        load_scenario(path)


def test_a_camera_on_an_unknown_frame_is_refused_at_its_line(tmp_path) -> None:
    path = tmp_path / "camera.yaml"
    path.write_text(
        "name: c\n"
        "robot: {name: franka_panda}\n"
        "duration: 1.0\n"
        "perception:\n"
        "  source: depth_camera\n"
        "  cameras:\n"
        "    - {name: head, position: [0, 0, 1], target: [1, 0, 0]}\n"
        "    - name: wrist\n"
        "      parent: panda_hnd\n"
    )
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    text = str(info.value)
    assert "line 9: perception.cameras[1].parent: no frame 'panda_hnd'" in text
    assert "panda_hand" in text


def test_a_scenario_names_a_urdf_and_includes_cat_by_name(tmp_path) -> None:
    """Any URDF arm with CAT's configuration: the goal frame is its end effector."""
    import pybullet_data

    urdf = Path(pybullet_data.getDataPath()) / "xarm" / "xarm6_robot.urdf"
    path = tmp_path / "s.yaml"
    path.write_text(
        f"name: xarm\ninclude: cat\nrobot: {{name: {urdf}}}\nduration: 1.0\n"
        "goal: {type: keyframes, keyframes: [{t: 0, pose: {position: [0.3, 0, 0.3]}}]}\n"
    )
    scenario = load_scenario(path)
    assert scenario.robot.nv == 6
    assert scenario.ee_frame == "link6"  # the last link of the longest chain
    assert scenario.goal_task() is not None
    assert scenario.spec.method.name == "cat"


def test_cbp_robot_init_writes_a_robot_folder_scenarios_can_use(tmp_path) -> None:
    import pybullet_data

    from tests.conftest import run_cbp

    urdf = Path(pybullet_data.getDataPath()) / "xarm" / "xarm6_robot.urdf"
    done = run_cbp(
        "robot", "init", str(urdf), "--out", str(tmp_path / "arm"), "--samples", "50"
    )
    assert done.returncode == 0, done.stderr
    assert "end effector: link6" in done.stdout
    assert "the visual meshes reach up to 2.0 mm past the collision shapes (link3)" in (
        done.stdout
    )
    text = (tmp_path / "arm" / "robot.yaml").read_text()
    assert "acceleration limits: 10.0 for every joint" in text  # said, in the file
    path = tmp_path / "s.yaml"
    path.write_text(
        "name: xarm\ninclude: cat\nrobot: {name: arm}\nduration: 1.0\n"
        "goal: {type: keyframes, keyframes: [{t: 0, pose: {position: [0.3, 0, 0.3]}}]}\n"
    )
    scenario = load_scenario(path)  # the robot path is the scenario's
    assert scenario.robot.name == "xarm6"
    assert scenario.robot.description is not None
    assert len(scenario.robot.description.collision.ignore_pairs) > 0


def test_cbp_prints_no_pybullet_banner_and_each_problem_once(tmp_path) -> None:
    from tests.conftest import run_cbp

    path = tmp_path / "dup.yaml"
    path.write_text("name: a\nname: b\nrobot: {name: franka_panda}\nduration: 1\n")
    done = run_cbp("-q", "check", str(path))
    assert done.returncode == 2
    assert done.stderr.count("duplicate key") == 1, done.stderr
    assert "pybullet build time" not in done.stdout + done.stderr
    boards = Path(__file__).resolve().parents[2] / "scenarios" / "cat_boards.yaml"
    done = run_cbp(
        "run", str(boards), "--set", "duration=0.2", "--out", str(tmp_path / "o")
    )
    assert "pybullet build time" not in done.stdout + done.stderr


def test_a_negative_self_filter_margin_is_refused_at_its_line(tmp_path) -> None:
    path = tmp_path / "margin.yaml"
    path.write_text(
        "name: m\n"
        "robot: {name: franka_panda}\n"
        "duration: 1.0\n"
        "perception:\n"
        "  source: depth_camera\n"
        "  cameras: [{name: head, position: [0, 0, 1], target: [1, 0, 0]}]\n"
        "  robot_margin: -0.01\n"
    )
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert "line 7: perception.robot_margin: must be in [0, 0.2] m, got -0.01" in str(
        info.value
    )


def test_a_section_given_in_part_keeps_its_defaults_in_the_parent() -> None:
    """method.mp.timing.clock alone keeps MP's 4 Hz period, not the class's 30 Hz."""
    path = SCENARIOS[0].parent / "cat_boards.yaml"
    plain = load_scenario(path, overrides={"method.name": "mp"})
    virtual = load_scenario(
        path, overrides={"method.name": "mp", "method.mp.timing.clock": "virtual"}
    )
    before, after = plain.spec.method.timing("mp"), virtual.spec.method.timing("mp")
    assert after.clock == "virtual"
    assert (after.period, after.max_period) == (before.period, before.max_period)
    assert after.period == 0.25


def test_unknown_keys_are_reported_at_their_own_line(tmp_path: Path) -> None:
    """A misspelt key is on its own line whatever its value: block, flow or plain."""
    error = _load(
        tmp_path,
        """\
        keyframe:              # line 4: top level, block list
          - {t: 0.0}
        wrold:                 # line 6: top level, block mapping
          objects: []
        duraton: 5.0           # line 8: top level, plain
        objetcs: {a: 1}        # line 9: top level, flow
        goal:
          type: keyframes
          keyframes:
            - {t: 0.0, pose: {position: [0.3, 0.0, 0.5]}}
          parmas:              # line 14: nested, block
            a: 1
          rat_hz: 30.0         # line 16: nested, plain
        tasks:
          - type: posture
            parmas:            # line 19: in a plugin entry, block
              joints: []
            wieght: [1.0]      # line 21: in a plugin entry, flow
            params:
              gian:            # line 23: plugin parameter, block
                - 1.0
        """,
    )
    lines = {p.split(": ", 2)[1]: p.split(":", 1)[0] for p in error.problems}
    assert lines == {
        "keyframe": "line 4",
        "wrold": "line 6",
        "duraton": "line 8",
        "objetcs": "line 9",
        "goal.parmas": "line 14",
        "goal.rat_hz": "line 16",
        "tasks[0].parmas": "line 19",
        "tasks[0].wieght": "line 21",
        "tasks[0].params.gian": "line 23",
    }


def test_bad_values_are_reported_at_the_value(tmp_path: Path) -> None:
    """A wrong value points at the value, also when it starts below its key."""
    error = _load(
        tmp_path,
        """\
        goal:
          type: keyframes
          rate_hz:
            - 30.0
          keyframes:
            - {t: 0.0, pose: {position: [0.3, 0.0, 0.5]}}
        tasks:
          - type: posture
            weight:
              a: 1.0
        """,
    )
    lines = {p.split(": ", 2)[1]: p.split(":", 1)[0] for p in error.problems}
    assert lines == {"goal.rate_hz": "line 7", "tasks[0].weight": "line 13"}


def test_unknown_key_from_set_is_reported_against_set(tmp_path: Path) -> None:
    """A key made by ``--set`` is located at the ``--set`` option, not at no line."""
    path = tmp_path / "s.yaml"
    path.write_text(HEADER)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path, overrides={"wrold.objects": "[]"})
    assert info.value.problems[0].startswith("--set wrold.objects: wrold: unknown key")


def test_a_keyframe_beyond_the_arms_reach_is_warned_of(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A goal beyond the arm's reach: a warning at its keyframe; others: none.

    The Panda's hand reaches 0.858 m from its shoulder: a goal 0.92 m away
    (within the 0.99 m of its joint origins' distances added up) is warned of.
    """
    path = tmp_path / "s.yaml"
    path.write_text(
        HEADER
        + textwrap.dedent(
            """\
            goal:
              type: keyframes
              keyframes:
                - {t: 0.0, pose: {position: [0.45, 0.0, 0.40]}}
                - t: 1.0
                  pose: {position: [0.92, 0.0, 0.333]}
                - {t: 2.0, pose: {position: [0.0, 0.0, 1.18]}}
            tasks:
              - type: goal_pose
            """
        )
    )
    with caplog.at_level("WARNING", logger="cbp.scenario.load"):
        load_scenario(path)
    warnings = [r.getMessage() for r in caplog.records]
    assert warnings == [
        f"{path}, line 8: goal.keyframes[1].pose.position: the goal [0.92, 0.0, "
        "0.333] at t = 1 s is out of reach of panda_hand: 0.92 m from the arm's "
        "first joint, beyond its reach (0.86 m, its links' lengths between their "
        "joints' axes); the arm stops short of it"
    ]


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_shipped_scenarios_warn_only_of_goals_out_of_reach(
    path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """No reachable goal is warned of; cat_unreachable's goal leaves the reach."""
    with caplog.at_level("WARNING", logger="cbp.scenario.load"):
        load_scenario(path)
    said = [r.getMessage() for r in caplog.records if "out of reach" in r.getMessage()]
    if path.stem == "cat_unreachable":
        assert [m.split(": ")[1] for m in said] == [
            "goal.keyframes[1].pose.position",
            "goal.keyframes[2].pose.position",
        ]
    else:
        assert said == []


def test_the_reach_bounds_every_configuration(robots: dict[str, Any]) -> None:
    """No configuration puts the hand farther from the first joint than the reach."""
    from scipy.optimize import minimize

    from cbp.scenario.reach import arm_reach
    from cbp.state import RobotState

    robot = robots["panda"]
    reach = arm_reach(robot, robot.neutral(), "panda_hand")
    assert reach is not None
    rng = np.random.default_rng(7)
    frame = robot.frame_id("panda_hand")
    farthest = 0.0
    for _ in range(2000):
        q = rng.uniform(robot.lower_limits, robot.upper_limits)
        farthest = max(
            farthest, reach.distance(RobotState(robot, q).frame_position(frame))
        )
    assert 0.8 * reach.radius < farthest <= reach.radius
    assert reach.radius == pytest.approx(0.858, abs=5e-4)  # Franka: 855 mm
    # Within its joint limits the hand comes within 2 mm of the bound.
    stretched = minimize(
        lambda q: -reach.distance(RobotState(robot, q).frame_position(frame)),
        robot.middle(),
        bounds=list(zip(robot.lower_limits, robot.upper_limits, strict=True)),
    )
    assert -stretched.fun > reach.radius - 0.002
    np.testing.assert_allclose(reach.centre, [0.0, 0.0, 0.333], atol=1e-6)
    assert (
        arm_reach(
            robots["panda_planar"], robots["panda_planar"].neutral(), "panda_hand"
        )
        is None
    )
