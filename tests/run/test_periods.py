"""The adaptive period settles at what the machine sustains; misses are counted."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cbp.run import build_run
from cbp.run.events import RunListener
from cbp.run.loop import run_loop
from cbp.run.periods import (
    FLOOR_HOLD,
    DeadlineMisses,
    LeadAdapter,
    PeriodAdapter,
)
from cbp.run.plan import Plan
from cbp.scenario import load_scenario
from cbp.sim.trajectory import time_parameterize

BOARDS = Path(__file__).resolve().parents[2] / "scenarios" / "cat_boards.yaml"


class _Starts(RunListener, list[float]):
    """The start times of the trajectories commanded."""

    def commanded(self, t: float) -> None:
        self.append(t)


def _misses(adapter: PeriodAdapter, seconds: float) -> int:
    """Misses of a loop that converges for 3 periods, then works for 1.

    Working, the planner fills its 80 % budget and the machine adds 6 ms the
    budget does not see (a loaded machine); converged, it takes 2 ms.
    """
    period, t, k, missed_count = 0.015, 0.0, 0, 0
    while t < seconds:
        compute = 0.8 * period + 0.006 if k % 4 == 3 else 0.002
        missed = compute > period
        missed_count += missed
        period = adapter.next(t, period, compute, missed)
        t += period
        k += 1
    return missed_count


def test_the_period_does_not_shrink_back_below_a_missed_one() -> None:
    """Misses held to about one per FLOOR_HOLD, not one in every working period."""
    settled = _misses(PeriodAdapter(0.015, 0.133, growth=1.5, shrink=0.9), 30.0)
    assert settled <= 2 * (1 + int(30.0 / FLOOR_HOLD))


def test_without_the_floor_the_period_oscillates(monkeypatch) -> None:
    """The same loop with no hold misses in most working periods."""
    from cbp.run import periods

    monkeypatch.setattr(periods, "FLOOR_HOLD", 0.0)
    oscillating = _misses(PeriodAdapter(0.015, 0.133, growth=1.5, shrink=0.9), 30.0)
    assert oscillating > 100


def test_the_floor_is_released_after_the_hold() -> None:
    """Once the machine keeps up for FLOOR_HOLD, the period shrinks to the shortest."""
    adapter = PeriodAdapter(0.015, 0.133, growth=1.5, shrink=0.9)
    period = adapter.next(0.0, 0.015, 0.02, missed=True)
    assert period == pytest.approx(0.0225)
    assert adapter.next(1.0, period, 0.001, missed=False) == pytest.approx(0.0225)
    t = FLOOR_HOLD + 0.1
    for _ in range(50):
        period = adapter.next(t, period, 0.001, missed=False)
        t += period
    assert period == pytest.approx(0.015)


def test_a_run_of_misses_is_said_in_a_few_events() -> None:
    """1000 misses in 15 s: the first at once, then at most one a second."""
    said: list[tuple[float, str]] = []
    misses = DeadlineMisses(lambda t, m: said.append((t, m)))
    for k in range(1000):
        misses.missed(k * 0.015, 0.02, 0.015, "result discarded")
    misses.met(15.0)
    assert misses.total == 1000
    assert said[0][1].startswith("deadline missed (20.0 ms for a 15.0 ms period)")
    assert len(said) <= 17
    counted = sum(int(m.split(" in ")[1].split()[0]) for _, m in said[1:])
    assert counted == 999
    assert said[-1][1].endswith("deadlines met again")


def test_a_single_miss_is_one_event() -> None:
    """An isolated miss is said once, with its figures; meeting again adds nothing."""
    said: list[tuple[float, str]] = []
    misses = DeadlineMisses(lambda t, m: said.append((t, m)))
    misses.missed(1.0, 0.04, 0.033, "result discarded")
    misses.met(1.033)
    misses.flush(2.0)
    assert [m for _, m in said] == [
        "deadline missed (40.0 ms for a 33.0 ms period): result discarded"
    ]


def test_the_lead_grows_after_a_late_plan_and_shrinks_back_within_its_bounds() -> None:
    """Late: times growth, up to the longest; in time: times shrink, to the shortest."""
    leads = LeadAdapter(0.006, 0.024, growth=1.5, shrink=0.9)
    assert leads.lead == 0.006
    leads.planned(in_time=False)
    assert leads.lead == pytest.approx(0.009)
    for _ in range(10):
        leads.planned(in_time=False)
    assert leads.lead == 0.024
    leads.planned(in_time=True)
    assert leads.lead == pytest.approx(0.0216)
    for _ in range(50):
        leads.planned(in_time=True)
    assert leads.lead == 0.006


class _SlowPlanner:
    """Plans a small move of the first joint once, with 2.5 periods of work."""

    def __init__(self, at: float, period: float) -> None:
        """Plan at the first period from ``at`` on."""
        self.at, self.period, self.calls = at, period, []

    def plan(self, q: Any, goal: Any, budget: Any, run: Any) -> Plan:
        """The move once (late); no motion otherwise."""
        if self.calls or run.arm.t < self.at - 1e-9:
            return Plan(None, 0, "holding")
        self.calls.append(run.arm.t)
        budget.charge("ik_iteration", int(2.5 * self.period / 26e-6))
        path = np.vstack([q, q + np.eye(q.size)[0] * 0.05])
        return Plan(path, 1, "moved")

    def close(self) -> None:
        """Nothing held."""


@pytest.mark.parametrize("moving", [False, True])
def test_a_late_plan_from_rest_is_commanded_when_ready_not_discarded(moving) -> None:
    """At rest where it starts, a late plan moves the robot from when it was ready.

    A late plan made while the robot still moves is discarded, as before.
    """
    scenario = load_scenario(
        BOARDS,
        overrides={
            "method.name": "ik",
            "duration": "1.0",
            "method.ik.timing.clock": "virtual",
            "method.ik.timing.period": "0.1",
        },
    )
    timing = scenario.spec.method.timing("ik")
    parts = build_run(scenario, method="ik", clock="virtual")
    if moving:  # a slow motion under way when the late plan is made
        q0 = parts.arm.q.copy()
        path = np.vstack([q0, q0 + np.eye(q0.size)[6] * 0.4])  # the wrist turns
        parts.arm.follow(
            time_parameterize(
                path,
                0.0,
                np.zeros(q0.size),
                np.zeros(q0.size),
                0.2 * parts.robot.velocity_limits,
                0.2 * parts.robot.acceleration_limits,
            )
        )
    planner = _SlowPlanner(0.3, timing.period)
    starts = _Starts()
    parts.log.listeners.append(starts)
    trace = run_loop(parts, planner, timing)
    events = "\n".join(message for _, message in trace.events)
    assert planner.calls == [pytest.approx(0.3)], events
    assert "deadline missed" in events
    moved = np.abs(trace.q_cmd[:, 0] - trace.q_cmd[0, 0]) > 1e-6
    if moving:
        assert "result discarded" in events
        assert starts == []
        assert not moved.any()
        return
    assert "used from rest at 0.55 s" in events
    assert starts == [pytest.approx(0.3 + 2.5 * timing.period, abs=1e-4)]
    assert not moved[trace.t < starts[0] - 1e-9].any()  # held until it was ready
    assert moved[-1]
