"""Input held to physics: obstacle speeds, goal-file cells and quaternions.

Each refused at ``cbp check`` and at load with its place (the scenario's line;
in a goal file its row and column), exit status 2; an obstacle faster than the
arm can retreat from is warned of at load, where the run would only say so as
it came.
"""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

import numpy as np
import pytest

from cbp.cli import main
from cbp.errors import ConfigError, DataFileError, ScenarioError
from cbp.goals import read_recorded
from cbp.scenario import load_scenario
from cbp.scenario.scene import MAX_OBJECT_SPEED, ObjectMotion

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"

#: The pushed-box scene with the box's velocity (m/s) left to fill in.
PUSHED = (
    (SCENARIOS / "cat_pushed_obstacle.yaml")
    .read_text()
    .replace("include: configs/cat.yaml", "include: cat")
    .replace("velocity: [0.0, -0.05, 0.0]", "velocity: [VELOCITY]")
)

RECORDED = """\
name: recorded
robot: {name: franka_panda}
duration: 2.0
goal:
  type: recorded
  file: goal.csv
tasks:
  - type: goal_pose
"""


def _pushed(tmp_path: Path, velocity: str) -> Path:
    path = tmp_path / "pushed.yaml"
    path.write_text(PUSHED.replace("VELOCITY", velocity))
    return path


def _recorded(tmp_path: Path, rows: str) -> Path:
    (tmp_path / "goal.csv").write_text("t,x,y,z,qx,qy,qz,qw\n" + textwrap.dedent(rows))
    path = tmp_path / "recorded.yaml"
    path.write_text(RECORDED)
    return path


def test_check_refuses_an_obstacle_faster_than_anything_tracked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """1e6 m/s (it tunnelled through the hand unseen): refused at its line."""
    path = _pushed(tmp_path, "1e6, 0, 0")
    assert main(["check", str(path)]) == 2
    assert capsys.readouterr().err == (
        f"{path}: 1 problem:\n"
        "  line 25: world.objects[1].motion.velocity: 1e+06 m/s is faster than "
        "any obstacle tracked near an arm (at most 20 m/s; a tool dropped from "
        "3 m lands at 8 m/s); faster, the simulator may move it through the arm "
        "between two steps\n"
    )


def test_the_same_speed_is_refused_from_python() -> None:
    """One rule for code and files: ObjectMotion refuses it too."""
    with pytest.raises(ConfigError, match=r"^velocity: 25 m/s is faster"):
        ObjectMotion(velocity=(0.0, 15.0, 20.0), stop=1.0)
    assert ObjectMotion(velocity=(MAX_OBJECT_SPEED, 0.0, 0.0), stop=1.0)


def test_an_obstacle_faster_than_the_arm_can_retreat_is_warned_of(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """10 m/s: a warning at load naming the speed, the bound and the link."""
    path = _pushed(tmp_path, "0.0, -10.0, 0.0")
    with caplog.at_level("WARNING", logger="cbp.scenario.load"):
        load_scenario(path)
    [warning] = [r.getMessage() for r in caplog.records]
    match = re.fullmatch(
        rf"{re.escape(str(path))}, line 25: world\.objects\[1\]\.motion\.velocity: "
        r"'box' moves at 10 m/s, faster than the arm can retreat along its path "
        r"\(at most (\d\.\d+) m/s at panda_\w+, the arm's part nearest the path "
        r"at the start, at the joints' velocity limits\): where it meets the arm, "
        r"contact is possible",
        warning,
    )
    assert match, warning
    assert 1.0 < float(match.group(1)) < 10.0


def test_an_obstacle_the_arm_can_outrun_is_not_warned_of(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The scene's own 5 cm/s, and 50 cm/s: no warning."""
    for velocity in ("0.0, -0.05, 0.0", "0.0, -0.5, 0.0"):
        with caplog.at_level("WARNING", logger="cbp.scenario.load"):
            load_scenario(_pushed(tmp_path, velocity))
    assert caplog.records == []


def test_check_refuses_a_goal_cell_that_is_no_number(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``abc`` in a goal file: the scenario's line, the file, row and column."""
    path = _recorded(
        tmp_path,
        """\
        0.0,0.4,0.0,0.4,1,0,0,0
        0.5,abc,0.0,0.4,1,0,0,0
        """,
    )
    assert main(["check", str(path)]) == 2
    assert capsys.readouterr().err == (
        f"{path}: 1 problem:\n"
        f"  line 6: goal.file: {tmp_path / 'goal.csv'}, row 3, column 2 (x): "
        "cannot read 'abc' as a number\n"
    )


def test_check_refuses_a_zero_quaternion(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A quaternion of norm 0 is no rotation: refused at its row and columns."""
    path = _recorded(
        tmp_path,
        """\
        0.0,0.4,0.0,0.4,1,0,0,0
        0.5,0.4,0.1,0.4,0,0,0,0
        """,
    )
    assert main(["check", str(path)]) == 2
    assert capsys.readouterr().err == (
        f"{path}: 1 problem:\n"
        f"  line 6: goal.file: {tmp_path / 'goal.csv'}, row 3, columns 5-8 (qx, "
        "qy, qz, qw): the quaternion (0, 0, 0, 0) has norm 0, expected 1 (a "
        "rotation; within 0.001)\n"
    )


def test_every_problem_of_a_goal_file_is_listed(tmp_path: Path) -> None:
    """Cells not finite, times that go back, a wrong count, a doubled quaternion."""
    path = _recorded(
        tmp_path,
        """\
        0.0,0.4,0.0,0.4,1,0,0,0
        0.5,0.4,0.0,0.4,1,0,0,0
        0.6,nan,0.0,0.4,1,0,0,0

        0.4,0.4,0.0,0.4,1,0,0,0
        0.7,0.4,0.0,inf,1,0,0,0
        0.8,0.4,0.0,0.4,1,0,0
        0.9,0.4,0.0,0.4,1,1,0,0
        """,
    )
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    csv = tmp_path / "goal.csv"
    finite = "expected a finite number of magnitude at most 1e+12, got"
    assert info.value.problems == [
        f"line 6: goal.file: {csv}, row 4, column 2 (x): {finite} nan",
        f"line 6: goal.file: {csv}, row 6, column 1 (t): times must increase; "
        "0.4 follows 0.5",
        f"line 6: goal.file: {csv}, row 7, column 4 (z): {finite} inf",
        f"line 6: goal.file: {csv}, row 8: expected 8 values, got 7",
        f"line 6: goal.file: {csv}, row 9, columns 5-8 (qx, qy, qz, qw): the "
        "quaternion (1, 1, 0, 0) has norm 1.414, expected 1 (a rotation; within "
        "0.001)",
    ]


def test_a_goal_file_of_many_bad_rows_lists_twenty(tmp_path: Path) -> None:
    """A thousand rows of zero quaternions: twenty listed, and how many more."""
    rows = "".join(f"{k / 30:.6f},0.4,0.0,0.4,0,0,0,0\n" for k in range(1000))
    with pytest.raises(DataFileError) as info:
        read_recorded(_recorded(tmp_path, rows).parent / "goal.csv")
    problems = info.value.problems
    assert len(problems) == 21
    assert problems[-1] == "and 980 more problems"


def test_a_quaternion_written_to_four_decimals_is_taken_as_a_rotation(
    tmp_path: Path,
) -> None:
    """0.7071 for 1/sqrt(2): within the tolerance, normalised."""
    path = _recorded(tmp_path, "0.0,0.4,0.0,0.4,0.7071,0,0,0.7071\n")
    stream = load_scenario(path).goal_stream()
    assert stream is not None
    _, rotation = stream.sample(0.0)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(rotation[1:, 1:], [[0.0, -1.0], [1.0, 0.0]], atol=1e-12)
