"""The orbit under acceleration limits, on scenarios written as a user would.

Each variant is a scenario file written here (not a shipped one) that lists its
own tasks and constraints, with the object, the desired distance's profile,
the operator's two-axis input and the obstacle moved about; one leaves out
``joint_acceleration``. Every one must keep the orbit paper's constraints:
distance within 2 cm and view within 1 deg after the transient, the altitude
and obstacle margins never negative, no step left unsolved.
"""

from __future__ import annotations

import logging
import textwrap
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cbp.engine import Engine
from cbp.engine.recovery import (
    CONSTRAINTS,
    EQUALITIES,
    LIMITS,
    POSITIONS,
    ease,
    give_way_levels,
)
from cbp.errors import SolveError
from cbp.executors.velocity import run_velocity
from cbp.metrics import run_metrics
from cbp.plugins.constraints.joint_acceleration_constraint import (
    JointAccelerationConstraint,
    JointAccelerationParams,
)
from cbp.plugins.constraints.joint_limits_constraint import (
    JointLimitsConstraint,
    JointLimitsParams,
)
from cbp.plugins.constraints.joint_velocity_constraint import (
    JointVelocityConstraint,
    JointVelocityParams,
)
from cbp.plugins.constraints.obstacle_distance_constraint import (
    ObstacleDistanceConstraint,
    ObstacleDistanceParams,
)
from cbp.plugins.constraints.orbit_distance_constraint import (
    OrbitDistanceConstraint,
    OrbitDistanceParams,
)
from cbp.plugins.constraints.view_direction_constraint import (
    ViewDirectionConstraint,
    ViewDirectionParams,
)
from cbp.plugins.tasks.goal_pose_task import GoalPoseParams, GoalPoseTask
from cbp.plugins.tasks.joint_step_task import JointStepParams, JointStepTask
from cbp.qp import Entry, QPProblem
from cbp.scenario import Scenario
from cbp.solvers import make_solver
from cbp.state import RobotState
from cbp.trace import Trace
from tests.conftest import load_virtual


@dataclass(frozen=True)
class Variant:
    """An orbit scenario as a user would write it."""

    name: str
    object: tuple[float, float, float] = (1.2, 0.0, 0.1)
    distance: str = "0.6"
    """r_d(t) [m]."""
    start: float = 0.6
    """r_d at t = 0 [m]."""
    v_y: str = "0.0"
    v_z: str = "0.0"
    obstacle: tuple[float, float] = (0.6, -1.0)
    min_distance: float = 0.6
    acceleration: bool = True
    """Whether the constraints list ``joint_acceleration``."""
    duration: float = 20.0

    def text(self) -> str:
        """The scenario file."""
        ox, oy, oz = self.object
        start = self.start
        rows = "  - {type: joint_acceleration, params: {margin: 0.05}}\n"
        return (
            textwrap.dedent(
                f"""\
            name: {self.name}
            robot: {{name: kuka_youbot}}
            method: {{name: velocity, velocity: {{dt: 0.02, transient_s: 5.0}}}}
            simulation: {{rate_hz: 500.0}}
            duration: {self.duration}
            inputs:
              - {{entry: user_velocity, values: ["{self.v_y}", "{self.v_z}"]}}
              - {{entry: distance, values: ["{self.distance}"]}}
            tasks:
              - {{type: camera_velocity, name: user_velocity, weight: 1000.0}}
              - {{type: joint_step, name: effort,
                 weight: [1.0, 1.0, 0.5, 0.2, 0.2, 0.2, 0.2, 0.2]}}
            constraints:
              - {{type: orbit_distance, name: distance, gain: 0.04,
                 params: {{object: [{ox}, {oy}, {oz}], distance: {start}}}}}
              - {{type: view_direction, name: view, gain: 0.04,
                 params: {{object: [{ox}, {oy}, {oz}]}}}}
              - {{type: no_roll, name: roll, gain: 0.04}}
              - {{type: min_altitude, name: altitude, gain: 0.04,
                 params: {{min_height: 0.25}}}}
              - {{type: obstacle_distance, name: obstacle, gain: 0.04,
                 params: {{obstacle: [{self.obstacle[0]}, {self.obstacle[1]}, 0.0],
                          min_distance: {self.min_distance}}}}}
              - {{type: joint_limits, params: {{margin: 0.05}}}}
              - {{type: joint_velocity}}
            """
            )
            + (rows if self.acceleration else "")
            + textwrap.dedent(
                f"""\
            world:
              objects:
                - {{name: cube, shape: box, size: [0.2, 0.2, 0.2],
                   pose: {{position: [{ox}, {oy}, {oz}]}}}}
            """
            )
        )


#: Held-out variants: object pose, distance profile, two-axis input, obstacle.
VARIANTS = [
    Variant(
        "object_moved",
        object=(1.3, 0.3, 0.15),
        distance="0.65 + 0.1 * smoothstep((t - 8) / 5)",
        start=0.65,
        v_y="0.12 * sin(2 * pi * t / 20)",
        v_z="0.03 * sin(2 * pi * t / 15)",
        obstacle=(0.5, -0.8),
    ),
    Variant(
        "fast_distance",
        distance="0.6 + 0.2 * smoothstep((t - 8) / 3) - 0.2 * smoothstep((t - 14) / 3)",
        v_y="0.1 * sin(2 * pi * t / 12)",
    ),
    Variant(
        "two_axis",
        object=(1.1, -0.2, 0.2),
        v_y="0.15 * sin(2 * pi * t / 10)",
        v_z="0.04 * cos(2 * pi * t / 8)",
        min_distance=0.5,
    ),
    Variant(
        "obstacle_slide",
        v_y="0.5 * smoothstep((t - 5) / 0.5)",
        v_z="0.03",
        obstacle=(0.9, -1.0),
    ),
    Variant(
        "obstacle_ahead",
        v_y="-0.8 * smoothstep((t - 5) / 0.5)",
        obstacle=(0.3, 0.8),
        min_distance=0.5,
    ),
    Variant(
        "object_to_the_side",  # 97 deg off the line of sight at the start
        object=(0.3, 0.9, 0.25),
        v_y="0.1 * sin(2 * pi * t / 10)",
        v_z="0.02",
        obstacle=(-0.8, -0.5),
        min_distance=0.5,
    ),
    Variant(
        "no_acceleration_entry",
        object=(1.25, -0.15, 0.12),
        distance="0.62 + 0.08 * smoothstep((t - 7) / 4)",
        start=0.62,
        v_y="0.1 * sin(2 * pi * t / 14)",
        v_z="0.02 * sin(2 * pi * t / 9)",
        acceleration=False,
    ),
]


@cache
def _run(variant: Variant, folder: Path) -> tuple[Scenario, Trace, dict[str, Any]]:
    path = folder / f"{variant.name}.yaml"
    path.write_text(variant.text())
    scenario = load_virtual(path)
    trace = run_velocity(scenario)
    return scenario, trace, run_metrics(trace, scenario.robot)


def _assert_orbit_holds(trace: Trace, metrics: dict[str, Any]) -> None:
    """Distance within 2 cm, view within 1 deg, margins >= 0, every step solved."""
    assert metrics["distance_error_max_m"] < 0.02
    assert metrics["view_error_max_deg"] < 1.0
    assert metrics["roll_max_deg"] < 1.0
    s = trace.signals
    assert np.all(s["altitude"] >= s["min_altitude"])  # every sample
    assert np.all(s["obstacle_distance"] >= s["min_obstacle_distance"])
    assert not [m for _, m in trace.events if "not solved" in m]
    assert metrics["base_travel_m"] > 0.3


@pytest.mark.slow
@pytest.mark.parametrize("variant", VARIANTS, ids=lambda v: v.name)
def test_held_out_orbit_variants_keep_their_constraints(
    variant: Variant, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """Each held-out variant keeps distance, view, roll and every margin."""
    folder = tmp_path_factory.mktemp("orbit")
    _, trace, metrics = _run(variant, folder)
    _assert_orbit_holds(trace, metrics)
    # The obstacle never gives way: its gain is what the base can brake.
    assert not [m for _, m in trace.events if "obstacle gave way" in m]


def test_a_short_orbit_without_acceleration_rows_moves_and_holds(
    tmp_path: Path,
) -> None:
    """Without ``joint_acceleration`` listed the rows are added and the base moves."""
    variant = Variant(
        "short",
        v_y="0.1 * smoothstep(t - 1)",
        v_z="0.02",
        acceleration=False,
        duration=7.0,
    )
    _, trace, metrics = _run(variant, tmp_path)
    _assert_orbit_holds(trace, metrics)
    added = [m for t, m in trace.events if t == 0.0 and "was added" in m]
    assert len(added) == 1
    assert "line 14: constraints" in added[0]


def test_the_loader_adds_the_acceleration_rows_and_says_where(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A velocity scenario listing no acceleration limit gets them, located."""
    path = tmp_path / "orbit.yaml"
    path.write_text(Variant("orbit", acceleration=False).text())
    with caplog.at_level(logging.WARNING, logger="cbp.scenario.load"):
        scenario = load_virtual(path)
    added = [e for e in scenario.entries if e.plugin.robot_limit == "acceleration"]
    assert [e.name for e in added] == ["joint_acceleration"]
    plugin = added[0].plugin
    assert isinstance(plugin, JointAccelerationConstraint)
    assert plugin.params.margin == 0.05  # the joint_limits entry's
    assert plugin.params.scale == 1.0
    assert added[0].priority == "hard"
    (record,) = caplog.records
    assert record.getMessage().startswith(f"{path}, line 14: constraints: ")
    assert "step guard checks" in record.getMessage()


def test_the_rows_are_not_added_twice_nor_where_the_guard_does_not_check(
    tmp_path: Path,
) -> None:
    """A scenario that lists them, or whose method checks no acceleration, is kept."""
    listed = tmp_path / "listed.yaml"
    listed.write_text(Variant("listed").text())
    entries = load_virtual(listed).entries
    assert sum(e.plugin.robot_limit == "acceleration" for e in entries) == 1
    kinematic = tmp_path / "kinematic.yaml"
    kinematic.write_text(
        Variant("kinematic", acceleration=False)
        .text()
        .replace(
            "name: velocity, velocity: {dt: 0.02, transient_s: 5.0}", "name: kinematic"
        )
    )
    entries = load_virtual(kinematic).entries
    assert not any(e.plugin.robot_limit == "acceleration" for e in entries)


# ---------------------------------------------------------------- what gives way


def _problem(rows: list[tuple[str, list[float], float, float]]) -> QPProblem:
    """A two-variable QP (min |x|^2) of named rows (entry, A row, lower, upper)."""
    names = list(dict.fromkeys(name for name, *_ in rows))
    lower = np.array([lo for *_, lo, _ in rows])
    upper = np.array([up for *_, up in rows])
    return QPProblem(
        H=np.eye(2),
        g=np.zeros(2),
        A=np.array([a for _, a, _, _ in rows], dtype=float),
        lower=lower,
        upper=upper,
        equality=lower == upper,
        row_entry=np.array([names.index(name) for name, *_ in rows]),
        entry_names=names,
        nv=2,
    )


def _ease(problem: QPProblem, levels: list[int]) -> tuple[np.ndarray, str]:
    solver = make_solver("daqp")
    with pytest.raises(SolveError) as info:
        solver.solve(problem)
    easable = np.array([level != LIMITS for level in levels])
    x, easing = ease(
        problem, info.value, 0.02, solver, easable, np.zeros(2), np.array(levels)
    )
    return x, easing.description


def test_the_tasks_give_way_before_an_obstacle() -> None:
    """A wall and a view that the braking joint cannot both meet: the view gives."""
    problem = _problem(
        [
            ("brakes", [1.0, 0.0], 0.010, 0.012),  # a joint braking: no easing
            ("speed", [0.0, 1.0], -0.05, 0.05),
            ("wall", [1.0, 1.0], 0.02, np.inf),
            ("view", [0.0, 1.0], 0.0, 0.0),
        ]
    )
    x, description = _ease(problem, [LIMITS, LIMITS, CONSTRAINTS, EQUALITIES])
    np.testing.assert_allclose(x, [0.012, 0.008], atol=1e-7)
    assert description.startswith("view gave way")


def test_an_obstacle_gives_way_only_by_what_the_limits_force() -> None:
    """A wall the braking joint cannot meet gives way by the least; the view holds."""
    problem = _problem(
        [
            ("brakes", [1.0, 0.0], 0.010, 0.012),
            ("wall", [1.0, 0.0], 0.02, np.inf),
            ("view", [0.0, 1.0], 0.0, 0.0),
        ]
    )
    x, description = _ease(problem, [LIMITS, CONSTRAINTS, EQUALITIES])
    np.testing.assert_allclose(x, [0.012, 0.0], atol=1e-7)
    assert description.startswith("wall gave way")


def test_a_wall_approached_faster_than_the_joint_brakes_gives_way_by_the_least() -> (
    None
):
    """No row asks for motion, yet the braking joint overshoots: it gives way."""
    problem = _problem(
        [
            ("brakes", [1.0, 0.0], 0.010, 0.012),  # still moving toward it
            ("wall", [1.0, 0.0], -np.inf, 0.008),  # standing still would do
            ("view", [0.0, 1.0], 0.0, 0.0),
        ]
    )
    x, description = _ease(problem, [LIMITS, CONSTRAINTS, EQUALITIES])
    np.testing.assert_allclose(x, [0.010, 0.0], atol=1e-7)  # braking its hardest
    assert description.startswith("wall gave way")


def test_the_give_way_levels_come_from_what_each_plugin_keeps(robots) -> None:
    """Acceleration and velocity limits never; position limits, then the rest."""
    robot = robots["youbot"]
    plugins = [
        JointAccelerationConstraint(JointAccelerationParams(), robot),
        JointVelocityConstraint(JointVelocityParams(), robot),
        JointLimitsConstraint(JointLimitsParams(), robot),
        ObstacleDistanceConstraint(ObstacleDistanceParams(), robot),
    ]
    assert give_way_levels(plugins).tolist() == [
        LIMITS,
        LIMITS,
        POSITIONS,
        CONSTRAINTS,
    ]


# ------------------------------------------------------------ ahead of the solve


def test_a_turning_base_ends_its_step_where_the_obstacle_row_said(robots) -> None:
    """The row bounds the value the step ends at, arc of a turning base included."""
    robot = robots["youbot"]
    obstacle = ObstacleDistanceConstraint(
        ObstacleDistanceParams(obstacle=(1.0, 0.0, 0.0), min_distance=0.5), robot
    )
    goal = GoalPoseTask(GoalPoseParams(frame="base_footprint"), robot)
    goal.set_target(np.array([2.0, 0.0, 0.0]), np.eye(3))  # through the obstacle
    k = 0.025
    engine = Engine(
        robot,
        [
            Entry.make(goal, weight=[1, 1, 0, 0, 0, 0], gain=0.5),
            Entry.make(JointStepTask(JointStepParams(), robot), weight=1e-3),
            Entry.make(obstacle, gain=k),
            Entry.make(JointVelocityConstraint(JointVelocityParams(), robot)),
            Entry.make(JointAccelerationConstraint(JointAccelerationParams(), robot)),
        ],
    )
    q = robot.home()
    q[0] = 0.499  # 1 mm from the bound
    v = np.zeros(robot.nv)
    v[1], v[2] = 0.6, -0.8  # sliding sideways, turning toward the obstacle
    state = RobotState(robot, q)
    margin = obstacle.compute_value(state)[0] - 0.5
    dq = engine.step(q, 0.02, v).dq
    state.update(robot.integrate(q, dq))
    after = obstacle.compute_value(state)[0] - 0.5
    assert after >= (1.0 - k) * margin  # the feedback form's promise, kept
    assert after < 1.01 * (1.0 - k) * margin  # and the row held the step


def test_the_view_rows_vanish_only_when_the_camera_looks_at_the_object(
    robots,
) -> None:
    """The image form's rows are as long as the angle off the line of sight."""
    robot = robots["youbot"]
    state = RobotState(robot)
    frame = robot.frame_id("camera_link")
    camera, rotation = state.frame_position(frame), state.frame_rotation(frame)
    for behind in (0.3, 1.0, 2.5, 3.1):  # [rad] off the line of sight
        direction = rotation.dot([np.cos(behind), np.sin(behind), 0.0])
        target = tuple(camera + 0.7 * direction)
        plugin = ViewDirectionConstraint(ViewDirectionParams(object=target), robot)
        value = plugin.compute_value(state)
        assert np.linalg.norm(value) == pytest.approx(behind)
        assert plugin.angle(state) == pytest.approx(behind)


def test_a_steady_distance_profile_is_followed_without_lag(robots) -> None:
    """orbit_distance says how far r_d moves over a step; a single jump is not."""
    plugin = OrbitDistanceConstraint(
        OrbitDistanceParams(distance=0.6), robots["youbot"]
    )
    state = RobotState(robots["youbot"])
    for r in (0.600, 0.602, 0.604):
        plugin.set_input(np.array([r]))
        plugin.prepare(state, 0.02)
    np.testing.assert_allclose(plugin.bound_change(), [0.002])
    plugin.set_input(np.array([0.7]))  # the operator's slider jumps
    plugin.prepare(state, 0.02)
    np.testing.assert_allclose(plugin.bound_change(), [0.002])  # the smaller
    plugin.prepare(state, 0.02)
    np.testing.assert_allclose(plugin.bound_change(), [0.0])  # held: no rate


def test_a_joint_brakes_before_its_limit_as_the_slowest_joint_can(robots) -> None:
    """An arm joint nears its limit no faster than the base could take over."""
    robot = robots["youbot"]
    q = robot.home()
    joint = robot.joint_q_slice("arm_joint_1").start
    tangent = robot.model.joints[robot.model.getJointId("arm_joint_1")].idx_v
    q[joint] = robot.upper_limits[joint] - 0.05 - 0.1  # 0.1 rad from where it stops
    state = RobotState(robot, q)
    dt = 0.02
    fastest = {}
    for braking in ("own", "slowest"):
        plugin = JointAccelerationConstraint(
            JointAccelerationParams(margin=0.05, braking=braking), robot
        )
        v = np.zeros(robot.nv)
        for _ in range(100):  # as fast toward the limit as the rows allow
            state.set_velocity(v)
            plugin.prepare(state, dt)
            v = np.zeros(robot.nv)
            v[tangent] = plugin.compute_bounds(state)[1][tangent] / dt
        fastest[braking] = v[tangent]
    for braking, a in (("own", 3.0), ("slowest", 1.0)):
        b = 1.5 * a * dt  # one tick at speed, then braking at a
        assert fastest[braking] == pytest.approx(-b + np.sqrt(b * b + 2 * a * 0.1))
