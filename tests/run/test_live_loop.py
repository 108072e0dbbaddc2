"""The paced trajectory loop: a goal that arrives mid-period is commanded at once.

The loop runs a real session's parts (the boards, CAT, PyBullet) on virtual
time: its budgets count work (``timing.clock: virtual``) and its pacer is a
clock the test moves, on which the operator's goals arrive at set times. What
is asserted does not depend on the machine's load.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cbp.run.events import RunListener
from cbp.run.live import COMMAND_LEAD, REPLAN_SHARE, SHOW_STEP, advance_in_step
from cbp.run.loop import run_loop
from cbp.run.pacing import MIN_BUDGET_SHARE, LoopClock
from cbp.sim.trajectory import JointTrajectory
from cbp.state import RobotState
from cbp.teleop import TeleopSession

BOARDS = Path(__file__).resolve().parents[2] / "scenarios" / "cat_boards.yaml"
#: A fixed command period [s] (no adaptation), so a test knows where periods end.
PERIOD = 0.03


class VirtualPacer:
    """Paces a live loop on virtual time; ``arrivals`` happen at their times.

    A wait that reaches an arrival's time runs it there (an operator's goal:
    it sets ``wake``); a wakeable wait ends at it, as the wall-clock pacer's
    does when a goal arrives.
    """

    def __init__(
        self, wake: threading.Event, arrivals: list[tuple[float, Callable[[], object]]]
    ) -> None:
        """Time 0, the arrivals to come."""
        self.now = 0.0
        self.wake = wake
        self.arrivals = sorted(arrivals, key=lambda a: a[0])

    def wait_until(self, t: float, wakeable: bool = True) -> float:
        """Move time to ``t``, or to the first arrival before it (wakeable)."""
        if t <= self.now:
            return self.now - t
        if wakeable and self.wake.is_set():
            return 0.0
        while self.arrivals and self.arrivals[0][0] <= t:
            at, arrive = self.arrivals.pop(0)
            self.now = max(self.now, at)
            arrive()
            if wakeable:
                return 0.0
        self.now = t
        return 0.0

    def left(self, t: float) -> float:
        """Virtual time until ``t``."""
        return t - self.now


class _Told(RunListener):
    """Hands what the run's log tells to the callables given."""

    def __init__(
        self,
        commanded: Callable[[float], object] | None = None,
        reached: Callable[[float], object] | None = None,
    ) -> None:
        self.on_commanded, self.on_reached = commanded, reached

    def commanded(self, t: float) -> None:
        if self.on_commanded is not None:
            self.on_commanded(t)

    def reached(self, t: float) -> None:
        if self.on_reached is not None:
            self.on_reached(t)


def _fixed_period_session(**more: str) -> TeleopSession:
    period = str(PERIOD)
    return TeleopSession(
        BOARDS,
        "cat",
        overrides={
            "duration": "0.75",
            "method.cat.timing.clock": "virtual",
            "method.cat.timing.period": period,
            "method.cat.timing.min_period": period,
            "method.cat.timing.max_period": period,
            **more,
        },
    )


def _run_with_arrival(
    at: float, **more: str
) -> tuple[
    TeleopSession,
    list[tuple[float, float]],
    list[tuple[float, JointTrajectory, JointTrajectory]],
]:
    """A session whose goal jogs 2 cm along +x at virtual time ``at``.

    Returns the session (run), each splice as (the pacer's time when it was
    made, its start time), and each trajectory change as (simulated time,
    the trajectory before, the one after).
    """
    session = _fixed_period_session(**more)
    sim = session.parts.arm
    follow = sim.follow
    changes: list[tuple[float, JointTrajectory, JointTrajectory]] = []

    def watched(trajectory: JointTrajectory, source: float | None = None) -> None:
        changes.append((sim.t, sim.trajectory, trajectory))
        follow(trajectory, source)

    sim.follow = watched  # type: ignore[method-assign]
    pacer = VirtualPacer(session.goal.arrived, [(at, lambda: session.jog("x", 0.02))])
    starts: list[tuple[float, float]] = []
    session.parts.log.listeners.append(
        _Told(commanded=lambda t_start: starts.append((pacer.now, t_start)))
    )
    run_loop(session.parts, session.planner, session.timing, LoopClock.paced(pacer))
    return session, starts, changes


def test_a_goal_that_arrives_mid_period_is_commanded_a_lead_later_not_at_its_end() -> (
    None
):
    """Spliced at arrival + lead < the period's end, from the commanded state then."""
    at = 10 * PERIOD + 0.25 * PERIOD  # early in the period [0.30, 0.33] s
    session, starts, changes = _run_with_arrival(at)
    lead = COMMAND_LEAD * PERIOD
    t_c = at + lead
    assert t_c < 11 * PERIOD  # what is asserted: before the period's end
    first = next(start for now, start in starts if now >= at)
    assert abs(first - t_c) < 1e-9, starts
    simulated, before, after = next(
        c for c in changes if np.any(np.abs(c[2].times - t_c) < 1e-9)
    )
    assert simulated <= t_c + 1e-12  # the robot had not been simulated past it
    k = int(np.argmin(np.abs(after.times - t_c)))
    # The new part starts from the state the robot was commanded to be in.
    q, v, a = before.sample(t_c)
    np.testing.assert_allclose(after.positions[k], q, atol=1e-12)
    np.testing.assert_allclose(after.velocities[k], v, atol=1e-12)
    np.testing.assert_allclose(after.accelerations[k], a, atol=1e-12)
    # Before t_c the commanded motion is unchanged (the quintic cut at t_c).
    for s in np.linspace(max(before.start_time, t_c - PERIOD), t_c, 7):
        np.testing.assert_allclose(after.sample(s)[0], before.sample(s)[0], atol=1e-9)
    # Within the limits, and toward the goal jogged along +x.
    robot = session.scenario.robot
    vmax = robot.velocity_limits * session.timing.velocity_scale
    assert np.all(np.abs(after.velocities[k + 1 :]) <= vmax * (1 + 1e-9))
    hand = robot.frame_id(session.scenario.ee_frame)
    start = RobotState(robot, after.positions[k]).frame_position(hand)
    end = RobotState(robot, after.positions[-1]).frame_position(hand)
    assert end[0] - start[0] > 0.002


def test_a_plan_made_after_its_lead_is_made_again_with_a_longer_lead() -> None:
    """A QP step longer than the lead: late, then made again from 1.5 leads on."""
    at = 10 * PERIOD + 0.25 * PERIOD
    lead = COMMAND_LEAD * PERIOD
    # One step (virtual time) costs more than a lead and fits in 1.5 leads;
    # half the period is the budget, so one step ends each period's plan.
    session, starts, _ = _run_with_arrival(
        at,
        **{
            "method.cat.timing.virtual_costs.qp_step": str(1.3 * lead),
            "method.cat.timing.time_budget": "0.5",
            # Room for the lead to grow (it is a share of the longest period).
            "method.cat.timing.max_period": str(2 * PERIOD),
        },
    )
    first = next(start for now, start in starts if now >= at)
    assert abs(first - (at + 1.5 * lead)) < 1e-9, starts
    notes = [p.note for p in session.parts.log.periods if p.t < at < p.t + p.period]
    assert notes[0].endswith("; 1 plan(s) made after their lead")


def test_a_goal_too_near_the_period_s_end_is_taken_by_the_next_period() -> None:
    """With less than REPLAN_SHARE of the period left, the next period plans for it."""
    at = 11 * PERIOD - 0.5 * REPLAN_SHARE * PERIOD
    _, starts, _ = _run_with_arrival(at)
    first = next(start for now, start in starts if now >= at)
    # Commanded by the next period's plan: from its first point after that
    # period's end on, not mid-period.
    assert first >= 12 * PERIOD - 1e-9


def test_unpaced_every_splice_starts_after_its_period_s_end() -> None:
    """Without a pacer the loop simulates while it plans: splices start at t_f or later."""
    session = _fixed_period_session()
    starts: list[float] = []
    session.parts.log.listeners.append(_Told(commanded=starts.append))
    run_loop(session.parts, session.planner, session.timing)
    ends = [p.t + p.period for p in session.parts.log.periods if p.spliced]
    assert len(ends) == len(starts)
    assert all(s >= e - 1e-9 for s, e in zip(starts, ends, strict=True))


class _OperatorDuringPlanning:
    """The session's planner; the operator jogs the goal while one plan is made."""

    def __init__(self, session: TeleopSession, at: float) -> None:
        """Jog at the plan of the period that starts at ``at``."""
        self.session, self.at, self.done = session, at, False

    def plan(self, q: Any, goal: Any, budget: Any, run: Any) -> Any:
        """Jog (once, in the chosen period), then plan as the session does."""
        if not self.done and run.arm.t >= self.at - 1e-9:
            self.done = True
            self.session.jog("x", 0.02)
        return self.session.planner.plan(q, goal, budget, run)

    def close(self) -> None:
        """Close the session's planner."""
        self.session.planner.close()


def test_a_goal_taken_while_the_period_is_planned_is_commanded_a_lead_later() -> None:
    """CAT takes it between its steps; it is planned for again at once, not at t_f."""
    session = _fixed_period_session()
    pacer = VirtualPacer(session.goal.arrived, [])
    starts: list[tuple[float, float]] = []
    session.parts.log.listeners.append(
        _Told(commanded=lambda t_start: starts.append((pacer.now, t_start)))
    )
    run_loop(
        session.parts,
        _OperatorDuringPlanning(session, 10 * PERIOD),
        session.timing,
        LoopClock.paced(pacer),
    )
    t_c = 10 * PERIOD + COMMAND_LEAD * PERIOD
    assert any(abs(start - t_c) < 1e-9 for _, start in starts), starts


def test_a_paced_loop_shows_the_robot_while_it_waits_never_past_a_lead() -> None:
    """``reached`` is told every SHOW_STEP of the wait, a lead ahead of now at most."""
    session = _fixed_period_session()
    pacer = VirtualPacer(session.goal.arrived, [(0.1, lambda: session.jog("x", 0.02))])
    shown: list[tuple[float, float]] = []
    session.parts.log.listeners.append(
        _Told(reached=lambda t: shown.append((pacer.now, t)))
    )
    run_loop(session.parts, session.planner, session.timing, LoopClock.paced(pacer))
    times = np.array([t for _, t in shown])
    assert np.all(np.diff(times) > -1e-12)  # the robot's time only goes on
    lead = COMMAND_LEAD * PERIOD
    assert all(t <= now + lead + 1e-9 for now, t in shown)
    periods = len(session.parts.log.periods)
    # Each period: its end, and the wait's steps before it.
    assert len(shown) >= periods * (PERIOD / SHOW_STEP - 2)
    gaps = np.diff(times)
    assert np.max(gaps) <= SHOW_STEP + lead + 1e-9


class _World:
    """A world whose simulation costs ``cost`` of the pacer's time per second."""

    def __init__(self, pacer: VirtualPacer, cost: float) -> None:
        self.pacer, self.cost = pacer, cost
        self.arm = self
        self.t = 0.0
        #: (simulated time reached, the pacer's time then) per advance.
        self.advances: list[tuple[float, float]] = []

    def advance(self, t: float, look_ahead: float, reaction: float) -> None:
        del look_ahead, reaction
        self.pacer.now += self.cost * max(0.0, t - self.t)
        self.t = max(self.t, t)
        self.advances.append((self.t, self.pacer.now))


def test_a_world_beside_its_cameras_is_simulated_no_faster_than_the_clock() -> None:
    """Each advance reaches at most the clock's time; a late world catches up."""
    pacer = VirtualPacer(threading.Event(), [])
    world = _World(pacer, cost=0.2)
    advance_in_step(pacer, world, 0.1, 0.3, 0.1)  # type: ignore[arg-type]
    assert world.t == 0.1
    for reached, now in world.advances[:-1]:
        assert reached <= now - 0.2 * SHOW_STEP + 1e-9  # begun at or before now
    assert len(world.advances) >= 0.1 / SHOW_STEP / 2
    # Behind the clock (a plan took 0.15 s): the world is simulated at once.
    pacer.now = 0.25
    advance_in_step(pacer, world, 0.2, 0.3, 0.1)  # type: ignore[arg-type]
    assert world.t == 0.2
    assert world.advances[-1][1] == pytest.approx(0.25 + 0.2 * 0.1)


def test_a_period_that_starts_late_plans_less() -> None:
    """The budget shrinks by the lateness, to a quarter of it at least."""
    pacer = VirtualPacer(threading.Event(), [])
    pacer.now = 1.0
    assert LoopClock().planning_time(0.024, 0.5) == 0.024  # unpaced: as configured
    paced = LoopClock.paced(pacer)
    assert paced.planning_time(0.024, 1.0) == 0.024  # on time
    assert paced.planning_time(0.024, 0.99) == pytest.approx(0.014)
    assert paced.planning_time(0.024, 0.5) == pytest.approx(MIN_BUDGET_SHARE * 0.024)
