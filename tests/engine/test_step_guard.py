"""The step guard: nothing the solver returns reaches the robot unchecked.

Faults are injected by wrapping the engine's solver: NaN answers, garbage steps
(1000 rad per joint), steps that end past a joint limit. Each is rejected like
a failed solve (the executors hold the robot and record an event); a step that
is only a little too fast is slowed down to the velocity limits.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cbp.engine import GARBAGE_RATIO, Engine
from cbp.errors import InvalidStateError, UnsafeStepError
from cbp.executors.kinematic import run_kinematic
from cbp.executors.velocity import run_velocity
from cbp.plugins.tasks.posture_task import PostureParams, PostureTask
from cbp.qp import Entry, QPProblem
from cbp.scenario import Scenario, load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


class FaultySolver:
    """Answers with ``fault(x)`` instead of the real solution every ``every`` calls."""

    def __init__(self, inner, fault, every: int = 1) -> None:
        """Wrap ``inner``; ``fault`` maps a solution to the answer given."""
        self.inner, self.fault, self.every = inner, fault, every
        self.calls = self.faults = 0

    def solve(self, problem: QPProblem) -> np.ndarray:
        """The inner solution, or every ``every``-th time the fault's."""
        x = self.inner.solve(problem)
        self.calls += 1
        if self.calls % self.every:
            return x
        self.faults += 1
        return self.fault(np.array(x))

    def __getattr__(self, name: str):
        """Everything else is the inner solver's."""
        return getattr(self.inner, name)


def _engine(robot) -> Engine:
    return Engine(robot, [Entry.make(PostureTask(PostureParams(), robot), gain=0.01)])


@pytest.mark.parametrize(
    ("fault", "message"),
    [
        (lambda x: np.full_like(x, np.nan), "not finite"),
        (lambda x: np.full_like(x, np.inf), "not finite"),
        (lambda x: np.full_like(x, 1000.0), "times its limit"),
    ],
    ids=["nan", "inf", "garbage"],
)
def test_a_bad_answer_is_rejected_naming_what_was_wrong(robots, fault, message):
    robot = robots["panda"]
    engine = _engine(robot)
    engine.solver = FaultySolver(engine.solver, fault)
    with pytest.raises(UnsafeStepError, match=message):
        engine.step(robot.home(), 0.01)


def test_a_step_past_a_joint_limit_is_rejected_and_one_back_is_kept(robots) -> None:
    robot = robots["panda"]
    engine = _engine(robot)
    q = robot.home()
    q[3] = robot.lower_limits[3] + 0.005
    push = -0.01  # 5 mm past the limit: within the speed bound, beyond the range

    def past(x: np.ndarray) -> np.ndarray:
        x[:] = 0.0
        x[3] = push
        return x

    engine.solver = FaultySolver(engine.solver, past)
    with pytest.raises(UnsafeStepError, match=r"'panda_joint4' would end 0\.005"):
        engine.step(q, 0.01)
    # A joint already past its limit may move back, not further out.
    q[3] = robot.lower_limits[3] - 0.02
    push = 0.01
    dq = engine.step(q, 0.01).dq
    assert dq[3] == pytest.approx(0.01)
    push = -0.001
    with pytest.raises(UnsafeStepError):
        engine.step(q, 0.01)


def test_a_step_a_little_too_fast_is_slowed_to_the_limits(robots) -> None:
    robot = robots["panda"]
    engine = _engine(robot)
    dt = 0.01
    limit = robot.velocity_limits * dt

    def twice(x: np.ndarray) -> np.ndarray:
        x[: robot.nv] = 0.0
        x[0] = 2.0 * limit[0]
        x[1] = 0.5 * limit[1]
        return x

    engine.solver = FaultySolver(engine.solver, twice)
    dq, _, _, slowed = engine.step(robot.home(), dt)
    assert slowed == pytest.approx(2.0 / 1.01, rel=1e-6)
    assert abs(dq[0]) <= engine.guard.speed_bound[0] * dt + 1e-15
    assert dq[1] / dq[0] == pytest.approx(0.25)  # the same direction
    assert GARBAGE_RATIO > 2.0


def test_a_step_that_accelerates_too_hard_is_rejected(robots) -> None:
    """Given the velocity the robot has, a jump past the acceleration limit."""
    robot = robots["panda"]
    engine = _engine(robot)
    dt = 0.01
    jump = 3.0 * robot.acceleration_limits[2] * dt  # rad/s in one step

    def sudden(x: np.ndarray) -> np.ndarray:
        x[: robot.nv] = 0.0
        x[2] = jump * dt
        return x

    engine.solver = FaultySolver(engine.solver, sudden)
    with pytest.raises(UnsafeStepError, match=r"'panda_joint3'.*acceleration limit"):
        engine.step(robot.home(), dt, np.zeros(robot.nv))
    # The same step from a velocity it is within reach of passes.
    v = np.zeros(robot.nv)
    v[2] = jump
    assert engine.step(robot.home(), dt, v).dq[2] == pytest.approx(jump * dt)
    # Without a velocity the guard checks no acceleration (kinematic executors
    # time their own trajectories).
    engine.step(robot.home(), dt)


@pytest.mark.parametrize(
    "v", [np.zeros(3), np.full(7, np.nan), np.full(7, np.inf), "fast"]
)
def test_the_engine_refuses_a_bad_velocity(robots, v) -> None:
    robot = robots["panda"]
    with pytest.raises(InvalidStateError, match="v "):
        _engine(robot).step(robot.home(), 0.01, v)


@pytest.mark.parametrize("dt", [0.0, -0.01, math.nan, math.inf, "0.01"])
def test_the_engine_refuses_a_bad_duration(robots, dt) -> None:
    robot = robots["panda"]
    with pytest.raises(InvalidStateError, match="dt must be"):
        _engine(robot).step(robot.home(), dt)


def test_the_engine_refuses_a_bad_configuration(robots) -> None:
    robot = robots["panda"]
    engine = _engine(robot)
    with pytest.raises(InvalidStateError, match="4 entries, expected nq = 7"):
        engine.step(np.zeros(4), 0.01)
    q = robot.home()
    q[2] = np.nan
    with pytest.raises(InvalidStateError, match="finite"):
        engine.step(q, 0.01)


def _with_faults(monkeypatch, fault, every: int) -> list[FaultySolver]:
    """Every engine a scenario makes from now on answers with ``fault``."""
    made: list[FaultySolver] = []
    original = Scenario.make_engine

    def make_engine(self, *args, **kwargs):
        engine = original(self, *args, **kwargs)
        engine.solver = FaultySolver(engine.solver, fault, every)
        made.append(engine.solver)
        return engine

    monkeypatch.setattr(Scenario, "make_engine", make_engine)
    return made


def test_the_kinematic_executor_holds_on_nan_and_goes_on(monkeypatch) -> None:
    made = _with_faults(monkeypatch, lambda x: np.full_like(x, np.nan), every=5)
    scenario = load_scenario(SCENARIOS / "panda_reach.yaml")
    trace = run_kinematic(scenario)
    assert made[0].faults > 10
    assert np.all(np.isfinite(trace.q))
    robot = scenario.robot
    assert np.all(trace.q >= robot.lower_limits - 1e-4)
    assert np.all(trace.q <= robot.upper_limits + 1e-4)
    rejected = [m for _, m in trace.events if "not finite" in m]
    assert len(rejected) == made[0].faults
    assert trace.position_error[-1] < 0.01  # and it still gets there


def test_the_velocity_executor_never_commands_garbage(monkeypatch) -> None:
    made = _with_faults(monkeypatch, lambda x: np.full_like(x, 50.0), every=4)
    scenario = load_scenario(
        SCENARIOS / "youbot_orbit_case1.yaml", overrides={"duration": "2.0"}
    )
    trace = run_velocity(scenario)
    assert made[0].faults > 5
    limits = scenario.robot.velocity_limits
    bound = np.where(np.isfinite(limits), 1.01 * limits + 1e-9, 10.0)
    assert np.all(np.abs(trace.u) <= bound)
    assert any("times its limit" in m for _, m in trace.events)


@pytest.mark.slow
@pytest.mark.parametrize(
    "fault",
    [lambda x: np.full_like(x, np.nan), lambda x: np.full_like(x, 1000.0)],
    ids=["nan", "garbage"],
)
def test_cat_crosses_the_boards_through_solver_faults(monkeypatch, fault) -> None:
    """One answer in seven is bad: no joint past its limit, no contact."""
    from cbp.executors.cat import run_cat
    from cbp.metrics import run_metrics
    from tests.conftest import load_virtual

    made = _with_faults(monkeypatch, fault, every=7)
    scenario = load_virtual(SCENARIOS / "cat_boards.yaml")
    trace = run_cat(scenario)
    assert sum(f.faults for f in made) > 50
    robot = scenario.robot
    assert np.all(trace.q >= robot.lower_limits - 0.01)
    assert np.all(trace.q <= robot.upper_limits + 0.01)
    m = run_metrics(trace)
    assert m["peak_contact_force_n"] == 0.0, m
    assert any("step rejected" in message for _, message in trace.events)
