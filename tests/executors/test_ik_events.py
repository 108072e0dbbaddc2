"""IK's events: once per episode of failure, out of reach named, counted at the end."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pinocchio as pin
import pytest

from cbp.executors.search_events import REPORT_AFTER, SearchEvents
from cbp.scenario import Scenario, load_scenario

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"
PERIOD = 1.0 / 30.0  # [s]


@pytest.fixture(scope="module")
def reach_scenario() -> Scenario:
    """The Panda reaching, on a fixed base (its reach is 0.858 m)."""
    return load_scenario(SCENARIOS / "panda_reach.yaml")


class FakeRun:
    """What SearchEvents reads of a run: its time, its scenario, its events."""

    def __init__(self, scenario: Scenario) -> None:
        """At t = 0, no events."""
        self.arm = SimpleNamespace(t=0.0)
        self.scenario = scenario
        self.events: list[tuple[float, str]] = []

    def event(self, t: float, message: str) -> None:
        """Record an event."""
        self.events.append((t, message))

    def messages(self) -> list[str]:
        """The events' messages, in order."""
        return [m for _, m in self.events]


def _goal(x: float, y: float = 0.0, z: float = 0.4) -> pin.SE3:
    return pin.SE3(np.eye(3), np.array([x, y, z]))


def _fail(
    events: SearchEvents, run: Any, goals: list[pin.SE3], exhausted: bool
) -> None:
    for goal in goals:
        events.failed(run, goal, exhausted=exhausted)
        run.arm.t += PERIOD


def test_a_goal_that_moves_every_period_is_said_once(reach_scenario: Scenario) -> None:
    """76 failing periods of a moving goal: one event, then one with the count."""
    run = FakeRun(reach_scenario)
    events = SearchEvents("ik")
    _fail(events, run, [_goal(0.5, 0.001 * k) for k in range(76)], exhausted=True)
    assert run.messages() == [
        "ik: no collision-free IK solution for the goal; the arm holds, and the "
        "search is tried again each period (said once until a solution is found)"
    ]
    events.solved(run)
    assert run.messages()[1] == (
        "ik: a collision-free IK solution found, after 76 periods (2.5 s) without one"
    )
    events.solved(run)  # solved again: nothing to say
    _fail(events, run, [_goal(0.5, 0.1)], exhausted=True)  # a new episode
    assert len(run.events) == 3
    assert "no collision-free IK solution" in run.messages()[2]


def test_a_goal_out_of_reach_is_called_out_of_reach(reach_scenario: Scenario) -> None:
    """Beyond the reach: said at once, as out of reach, once however it moves."""
    run = FakeRun(reach_scenario)
    events = SearchEvents("ik")
    far = [_goal(1.5, 0.01 * k, 0.3) for k in range(20)]
    _fail(events, run, far, exhausted=False)  # even searches cut short
    assert len(run.events) == 1
    message = run.messages()[0]
    assert message.startswith(
        "ik: no IK solution for the goal, out of reach: 1.50 m from the arm's first "
        "joint, beyond its reach (0.86 m"
    )
    assert events.beyond_reach(run, _goal(1.5)) is not None  # type: ignore[arg-type]
    assert events.beyond_reach(run, _goal(0.5)) is None  # type: ignore[arg-type]


def test_a_changed_reason_is_said_again(reach_scenario: Scenario) -> None:
    """Within reach and failing, then out of reach: a second event names the reach."""
    run = FakeRun(reach_scenario)
    events = SearchEvents("ik")
    _fail(events, run, [_goal(0.5)] * 3, exhausted=True)
    _fail(events, run, [_goal(1.5)] * 3, exhausted=True)
    _fail(events, run, [_goal(1.6)] * 3, exhausted=True)
    messages = run.messages()
    assert len(messages) == 2, messages
    assert "out of reach" not in messages[0]
    assert "out of reach" in messages[1]


def test_searches_cut_short_are_said_after_a_while_even_as_the_goal_moves(
    reach_scenario: Scenario,
) -> None:
    """Budget-cut searches of a moving goal: said once REPORT_AFTER has passed."""
    run = FakeRun(reach_scenario)
    events = SearchEvents("ik")
    periods = int(REPORT_AFTER / PERIOD)
    _fail(events, run, [_goal(0.5, 0.001 * k) for k in range(periods)], False)
    assert run.events == []
    _fail(events, run, [_goal(0.5, 0.2)] * 10, exhausted=False)
    assert len(run.events) == 1
    assert "searches cut short by the period's budget" in run.messages()[0]


def test_a_failure_to_the_end_of_the_run_is_counted(reach_scenario: Scenario) -> None:
    """The run ends while the goal is unsolved: an event says for how long."""
    run = FakeRun(reach_scenario)
    events = SearchEvents("ik")
    _fail(events, run, [_goal(1.5)] * 30, exhausted=True)
    events.close()
    assert run.messages()[-1] == (
        "ik: still no IK solution at the end of the run, after 30 periods (1.0 s) "
        "without one"
    )
    events.close()  # nothing more
    assert len(run.events) == 2


def test_mp_says_a_failure_still_going_on_when_it_closes(
    reach_scenario: Scenario,
) -> None:
    """MP's planner, closed at the run's end, counts the failure as IK's does."""
    from cbp.executors import make_planner
    from cbp.run import build_run

    parts = build_run(reach_scenario, method="mp", clock="virtual")
    try:
        planner = make_planner("mp", parts)
        run = FakeRun(reach_scenario)
        _fail(planner.events, run, [_goal(1.5)] * 30, exhausted=True)
        planner.close()
    finally:
        parts.close()
    assert run.messages()[-1] == (
        "mp: still no IK solution at the end of the run, after 30 periods (1.0 s) "
        "without one"
    )
