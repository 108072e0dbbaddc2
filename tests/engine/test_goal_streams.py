"""Goal streams (function, recorded), includes and --set overrides."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from cbp.errors import ConfigError, ScenarioError
from cbp.expressions import compile_time_function
from cbp.goals import RecordedGoal, RecordedGoalSpec, write_recorded
from cbp.scenario import load_scenario

GOAL_TASK = """\
tasks:
  - type: goal_pose
    params: {frame: panda_hand}
"""


def _write(path: Path, text: str, tasks: str = "") -> Path:
    path.write_text(textwrap.dedent(text) + tasks)
    return path


def test_expressions_are_functions_of_time() -> None:
    f = compile_time_function("0.1 * sin(2 * pi * 0.5 * t) + where(t > 1, 0.2, 0)")
    assert f(0.5) == pytest.approx(0.1)
    assert f(1.5) == pytest.approx(0.1 * np.sin(1.5 * np.pi) + 0.2)
    assert compile_time_function(3)(7.0) == 3.0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("sinn(t)", "unknown function 'sinn'.*'sin'"),
        ("t.__class__", "Attribute is not allowed"),
        ("open('x')", "unknown function 'open'"),
        ("2 * tt", "unknown name 'tt'"),
        ("sin('x')", "only numbers are allowed"),
        ("1 +", "not an expression"),
        ("log(t)", "fails at t = 0"),
    ],
)
def test_bad_expressions_are_refused_with_the_reason(text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        compile_time_function(text, "function.position[1]")


def test_function_goal(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "s.yaml",
        """\
        name: t
        robot: {name: franka_panda}
        duration: 1.0
        goal:
          type: function
          function:
            position: [0.4, "0.1 * sin(2 * pi * t)", 0.5]
            rpy_deg: [180, 0, "10 * t"]
        """,
        GOAL_TASK,
    )
    stream = load_scenario(path).goal_stream()
    assert stream is not None
    p, R = stream.sample(0.25)
    np.testing.assert_allclose(p, [0.4, 0.1, 0.5])
    np.testing.assert_allclose(
        pin.rpy.matrixToRpy(R), np.deg2rad([180, 0, 2.5]), atol=1e-9
    )


def test_recorded_goal_round_trip(tmp_path: Path) -> None:
    """A written recording replays, interpolated between its samples."""
    times = [0.0, 0.5, 1.0]
    positions = np.array([[0.3, 0.0, 0.5], [0.4, 0.1, 0.5], [0.5, 0.2, 0.5]])
    rotations = np.array([np.diag([1.0, -1.0, -1.0])] * 3)
    write_recorded(tmp_path / "goal.csv", times, positions, rotations)
    stream = RecordedGoal(RecordedGoalSpec(file="goal.csv"), tmp_path)
    p, R = stream.sample(0.25)
    np.testing.assert_allclose(p, [0.35, 0.05, 0.5])
    np.testing.assert_allclose(R, rotations[0], atol=1e-9)
    np.testing.assert_allclose(stream.sample(1.0)[0], [0.5, 0.2, 0.5])
    assert stream.end_time == 1.0


def test_recorded_goal_errors_name_the_file(tmp_path: Path) -> None:
    (tmp_path / "bad.csv").write_text("time,x,y\n0,1,2\n")
    path = _write(
        tmp_path / "s.yaml",
        """\
        name: t
        robot: {name: franka_panda}
        duration: 1.0
        goal: {type: recorded, file: bad.csv}
        """,
        GOAL_TASK,
    )
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    text = str(info.value)
    assert "goal.file" in text
    assert "t,x,y,z,qx,qy,qz,qw" in text


def test_goal_type_needs_its_fields(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "s.yaml",
        """\
        name: t
        robot: {name: franka_panda}
        duration: 1.0
        goal: {type: function, file: goal.csv}
        """,
        GOAL_TASK,
    )
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.problems == [
        "line 4: goal.file: unknown key 'file' Accepted: type, task, rate_hz, "
        "function.",
        "line 4: goal.function: missing required key 'function' (a mapping "
        "(PoseExpressions))",
    ]


def test_include_merges_and_locates_problems_in_the_included_file(
    tmp_path: Path,
) -> None:
    _write(
        tmp_path / "base.yaml",
        """\
        duration: 2.0
        tasks:
          - type: goal_pose
            params: {frame: panda_hand, max_step_translaton: 0.01}
        """,
    )
    path = _write(
        tmp_path / "s.yaml",
        """\
        name: t
        include: base.yaml
        robot: {name: franka_panda}
        duration: 1.0
        """,
    )
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    text = str(info.value)
    assert f"{tmp_path / 'base.yaml'}, line 4" in text
    assert "max_step_translation" in text  # the suggestion
    _write(
        tmp_path / "base.yaml",
        """\
        duration: 2.0
        tasks:
          - type: goal_pose
            params: {frame: panda_hand}
        """,
    )
    scenario = load_scenario(path)
    assert scenario.spec.duration == 1.0  # the including file wins
    assert [e.name for e in scenario.entries] == ["goal_pose"]


def test_missing_include_is_reported(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "s.yaml",
        """\
        name: t
        include: [nowhere.yaml]
        robot: {name: franka_panda}
        duration: 1.0
        """,
    )
    with pytest.raises(ScenarioError, match=r"include: .*nowhere\.yaml"):
        load_scenario(path)


def test_set_overrides_values_and_reports_bad_ones(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "s.yaml",
        """\
        name: t
        robot: {name: franka_panda}
        duration: 1.0
        """,
    )
    scenario = load_scenario(
        path, overrides={"duration": "3.5", "collision.activation_distance": "0.2"}
    )
    assert scenario.spec.duration == 3.5
    assert scenario.spec.collision.activation_distance == 0.2
    with pytest.raises(ScenarioError) as info:
        load_scenario(path, overrides={"perception.source": "depth_camra"})
    text = str(info.value)
    assert "--set perception.source" in text
    assert "depth_camera" in text


def test_set_with_an_unknown_key_on_the_way_is_a_located_problem(
    tmp_path: Path,
) -> None:
    """``--set`` makes the missing mappings; an unknown key among them is reported."""
    path = _write(
        tmp_path / "s.yaml",
        """\
        name: t
        robot: {name: franka_panda}
        duration: 1.0
        """,
    )
    with pytest.raises(ScenarioError) as info:
        load_scenario(path, overrides={"perception.cameras[2].near": "0.1"})
    assert "unknown key 'cameras[2]'" in str(info.value)


def test_every_goal_kind_is_in_the_table_once_and_sorted() -> None:
    """Each GoalStream of cbp/goals/ is a row, its section's type its name."""
    import importlib
    import pkgutil

    import cbp.goals
    from cbp.goals import GOAL_KINDS, GoalSpec, GoalStream

    defined = set()
    for module in pkgutil.iter_modules(cbp.goals.__path__):
        found = importlib.import_module(f"cbp.goals.{module.name}")
        defined |= {
            cls
            for cls in vars(found).values()
            if isinstance(cls, type)
            and issubclass(cls, GoalStream)
            and cls is not GoalStream
            and cls.__module__ == found.__name__
        }
    assert defined == set(GOAL_KINDS.values())
    assert list(GOAL_KINDS) == sorted(GOAL_KINDS)
    for name, kind in GOAL_KINDS.items():
        assert kind.type_name == name
        assert kind.Spec.__dataclass_fields__["type"].default == name
        assert GoalSpec.variants()[name] is kind.Spec


def _goal_problems(tmp_path: Path, goal: str) -> list[str]:
    """The problems of a scenario whose goal section is ``goal`` (YAML lines)."""
    path = tmp_path / "s.yaml"
    path.write_text(
        "name: t\nrobot: {name: franka_panda}\nduration: 1.0\n" + goal + GOAL_TASK
    )
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    return info.value.problems


def test_a_goal_type_not_in_the_table_lists_the_kinds(tmp_path: Path) -> None:
    """A misspelt type: the nearest kind and every kind, at its line."""
    assert _goal_problems(tmp_path, "goal:\n  type: keyfrmes\n  keyframes: []\n") == [
        "line 5: goal.type: got 'keyfrmes', expected one of 'function', "
        "'keyframes', 'recorded', 'step'; did you mean 'keyframes'?"
    ]
    assert _goal_problems(tmp_path, "goal: {rate_hz: 10}\n") == [
        "line 4: goal.type: missing required key 'type' (one of 'function', "
        "'keyframes', 'recorded', 'step')"
    ]


def test_a_goal_section_is_read_as_its_kind(tmp_path: Path) -> None:
    """Only the kind's own keys; its checks at their line."""
    assert _goal_problems(
        tmp_path,
        "goal:\n  type: step\n  keyframes: []\n  function: {position: [0, 0, 0]}\n",
    ) == [
        "line 7: goal.function: unknown key 'function' Accepted: type, task, "
        "rate_hz, keyframes.",
    ]
    assert _goal_problems(tmp_path, "goal:\n  type: step\n  keyframes: []\n") == [
        "line 6: goal.keyframes: needs at least one keyframe"
    ]


def test_a_goal_section_made_in_python_is_its_kinds() -> None:
    """The same rule as in a file: the base section names no kind of its own."""
    from cbp.goals import GoalSpec, Keyframe, KeyframesGoalSpec, StepGoalSpec
    from cbp.spatial import Pose

    with pytest.raises(ConfigError, match=r"not the section of a 'step' goal \(Step"):
        GoalSpec(type="step")
    with pytest.raises(ConfigError, match="kinds: function, keyframes, recorded"):
        KeyframesGoalSpec(type="spline", keyframes=[])
    keyframe = Keyframe(t=0.0, pose=Pose(position=(0.4, 0.0, 0.4)))
    assert StepGoalSpec(keyframes=[keyframe]).type == "step"
