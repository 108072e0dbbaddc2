# SPDX-License-Identifier: Apache-2.0
"""Trajectory executors: plan each command period, time it, splice it in.

The loop of CAT Sec. IV-D, shared by every method that sends joint trajectories
to the low-level follower (CAT, and the IK and MP methods):

1. At the start of a period (time t, length P) the operator's latest goal is
   taken. The deadline is t_f = t + P. In a live session, a goal that arrives
   after the planning is planned for again in the time left before t_f
   (the wall-clock pacer's wait ends on it), so it too is commanded at t_f.
2. The planning starts from the first point of the current trajectory scheduled
   after t_f (its position, velocity and acceleration), so the robot keeps
   moving while the planner works.
3. The planner returns a path of configurations within its budget: wall-clock
   time, or counted work with ``timing.clock: virtual``
   (:mod:`cbp.executors.clock`).
4. The path is time-parameterized so that every joint can stop at its end
   within the velocity and acceleration limits (no inevitable collision state),
   and spliced in at that starting point with continuous position and velocity.
   A result computed after the deadline is discarded; so is one that cannot stop
   in time from the starting velocity (the current trajectory, which does stop,
   goes on).
5. The period adapts: longer after a miss, shorter when time was spare, but
   not below what the machine sustains (:mod:`cbp.executors.periods`); misses
   are counted, not listed one by one.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
import pinocchio as pin

from cbp.collision.world import CollisionWorld
from cbp.compilation import CompileCounter
from cbp.engine import Engine
from cbp.executors.backout import back_out
from cbp.executors.clock import Budget, make_budget
from cbp.executors.periods import DeadlineMisses, PeriodAdapter
from cbp.methods.settings import ExecutorTiming
from cbp.robot import FloatArray
from cbp.run.pacing import WallClockPacer
from cbp.run.parts import RunParts, build_run
from cbp.scenario.runtime import Scenario
from cbp.sim.trajectory import JointTrajectory, time_parameterize
from cbp.trace import PeriodRecord, Trace

__all__ = [
    "Plan",
    "Planner",
    "StepsAnEngine",
    "run_periodic",
    "run_trajectory_executor",
    "stopping_trajectory",
]


@dataclass
class Plan:
    """A planner's answer for one period.

    Attributes:
        path: configurations from the start point on (the first is the start),
            or None for no motion (keep the current trajectory).
        steps: planning steps taken (QP steps, interpolation checks, ...).
        note: what ended the computation or why there is no path.
        timed_out: the planner ran out of time before it had a result (a miss:
            the period grows).
        stop: brake along the current trajectory now (no path): the robot
            comes to rest as soon as its limits allow (:func:`stopping_trajectory`).
    """

    path: FloatArray | None
    steps: int = 0
    note: str = ""
    timed_out: bool = False
    stop: bool = False


class Planner(Protocol):
    """Computes a path each command period (CAT, IK, MP, hybrid)."""

    def plan(
        self, q: FloatArray, goal: pin.SE3 | None, budget: Budget, run: RunParts
    ) -> Plan:
        """Path from ``q`` toward ``goal`` within ``budget``, charging its work."""
        ...

    def close(self) -> None:
        """Release what the planner holds (threads, processes); idempotent."""
        ...


@runtime_checkable
class StepsAnEngine(Protocol):
    """A planner that steps a QP engine (CAT, and the hybrid's CAT).

    A live page shows the contacts its contact rows hold.
    """

    @property
    def engine(self) -> Engine:
        """The engine it steps."""
        ...


def run_periodic(scenario: Scenario, method: str, gui: bool = False) -> Trace:
    """Run ``scenario`` with periodic method ``method``; return the trace.

    The one runner of every method that plans per command period (the
    ``run_<name>`` of CAT, IK, MP and the hybrid): its parts from
    :func:`~cbp.run.build_run`, its planner from the method's module, the
    loop's timing from the scenario's ``method:`` section.
    """
    from cbp.executors import make_planner

    timing = scenario.spec.method.timing(method)
    parts = build_run(scenario, method=method, gui=gui, clock=timing.clock)
    try:
        planner = make_planner(method, scenario, parts)
    except BaseException:
        parts.close()
        raise
    return run_trajectory_executor(parts, planner, timing)


#: The back-out path's points are at most this far apart in time at full speed [s].
BACK_OUT_DT = 0.02


class _LeavingContact:
    """Backs the robot out of an obstacle before any method plans.

    Against declared objects only: in an occupancy map, contact with cells is
    not contact with a surface (the map holds it to half a cell, and unseen
    space counts as an obstacle), and the methods' own rules handle it.
    """

    def __init__(self, run: RunParts, step_bound: FloatArray) -> None:
        self.run = run
        self.step_bound = step_bound
        self.since: float | None = None

    def plan(self, t: float, q: FloatArray) -> Plan | None:
        """A back-out plan from ``q``, or None when the robot touches nothing."""
        world = self.run.world
        if world is None or world.environment.resolution > 0.0:
            return None
        path, depth = back_out(world, q, self.step_bound)
        if path is None:
            if self.since is not None:
                self.run.event(
                    t, f"out of contact after {t - self.since:.2f} s of backing out"
                )
                self.since = None
            return None
        if self.since is None:
            self.since = t
            self.run.event(
                t,
                f"in contact with an obstacle, {depth * 1e3:.1f} mm deep: backing "
                "out along the contact normals before planning",
            )
        return Plan(path, len(path) - 1, "backing out of contact")


def held(world: CollisionWorld | None) -> contextlib.AbstractContextManager[object]:
    """``world``'s snapshot held while a plan is made (nothing without a world)."""
    return contextlib.nullcontext() if world is None else world.holding()


def _never() -> bool:
    return False


def run_trajectory_executor(
    run: RunParts,
    planner: Planner,
    timing: ExecutorTiming,
    *,
    pacer: WallClockPacer | None = None,
    stop_requested: Callable[[], bool] = _never,
    commanded: Callable[[float], None] | None = None,
) -> Trace:
    """Run the scenario with ``planner`` each command period; return the trace.

    A period in which something raises (the planner, the goal input, the
    simulator) holds the robot: it brakes along the trajectory it is on
    (:func:`stopping_trajectory`), and the exception is an event. So does a
    period in which the run says the robot must hold
    (:meth:`RunParts.hold_reason`: a camera that gives no valid frames).
    After :data:`~cbp.run.faults.MAX_FAULTS_IN_A_ROW` failing periods the
    run is aborted: the robot stops, and the trace ends there with the reason.
    The planner is closed at the end.

    Args:
        run: the run's parts (:func:`cbp.run.build_run`).
        planner: plans each period.
        timing: the command period, budget and limits.
        pacer: keeps the loop in step with the wall clock (a live session);
            None runs as fast as the work allows.
        stop_requested: asked at each period's start; True ends the run
            there (an operator's stop).
        commanded: called with the start time of each trajectory spliced in.
    """
    robot = run.robot
    vmax = robot.velocity_limits * timing.velocity_scale
    amax = robot.acceleration_limits * timing.acceleration_scale
    lo, hi = timing.bounds()
    period = timing.period
    stop_time = robot.stopping_time(vmax, amax)
    t = 0.0
    sim = run.sim
    faults = run.faults
    adapter = PeriodAdapter(lo, hi, timing.growth, timing.shrink)
    leaving = _LeavingContact(run, vmax * BACK_OUT_DT)
    misses = DeadlineMisses(run.event)
    compiles = CompileCounter.install()
    try:
        while (
            t < run.duration - 1e-9 and faults.aborted is None and not stop_requested()
        ):
            t_f = t + period
            current = sim.trajectory
            i = current.first_point_after(t_f)
            if i is None:
                t_s, q_s = t_f, current.positions[-1]
                v_s = a_s = np.zeros_like(q_s)
            else:
                t_s, q_s, v_s, a_s = current.point(i)
            budget = make_budget(
                timing.clock,
                timing.time_budget * period,
                timing.virtual_costs,
                horizon=period,
            )
            # The plan made now starts a period from now and runs until the next
            # one replaces it, a period later; from there the robot may need its
            # stopping time to get out of the way. Moving obstacles are measured
            # that far ahead (as speed and separation monitoring counts them).
            look_ahead = 2.0 * period + stop_time
            new: JointTrajectory | None = None
            failed = False
            compiled = compiles.count
            hold: str | None = None
            backing: Plan | None = None
            try:
                goal = run.goal.send(t)
                hold = run.hold_reason(t)
                if hold is not None:
                    plan = Plan(None, 0, hold)
                else:
                    # One snapshot of the obstacles for the whole plan.
                    with held(run.world):
                        backing = leaving.plan(t, q_s)
                        plan = backing or planner.plan(q_s.copy(), goal, budget, run)
                note = plan.note
                if plan.path is not None and len(plan.path) > 1:
                    new = time_parameterize(plan.path, t_s, v_s, a_s, vmax, amax)
                    budget.charge("trajectory_point", len(plan.path))
                    if new is None:
                        note = "path too short to stop on; current trajectory kept"
            except Exception as exc:  # any failure: hold the robot, say so
                failed = True
                plan = Plan(None, 0, faults.fault(t, "planning", exc))
                note = plan.note
            if (failed or hold is not None or plan.stop) and i is not None:
                new = stopping_trajectory(current, i, vmax, amax)
            compute = budget.elapsed()
            timed_out, steps = plan.timed_out, plan.steps
            try:
                # The robot moves on while the result is computed.
                run.advance(t_f, look_ahead, reaction=2.0 * period)
                if pacer is not None:
                    pacer.wait_until(t_f)
            except Exception as exc:
                failed = True
                note = faults.fault(t, "simulation", exc)
            if pacer is not None and not (
                failed or hold is not None or backing is not None or plan.stop
            ):
                try:
                    again = _plan_while_waiting(
                        pacer, t, t_f, q_s, planner, run, timing, lo, period
                    )
                except Exception as exc:  # as a failing period: hold the robot
                    failed = True
                    plan = Plan(None, 0, faults.fault(t, "planning", exc))
                    note = plan.note
                    again = None
                    if i is not None:
                        new = stopping_trajectory(current, i, vmax, amax)
                if again is not None:
                    steps += again.steps
                    timed: JointTrajectory | None = None
                    if again.path is not None and len(again.path) > 1:
                        timed = time_parameterize(again.path, t_s, v_s, a_s, vmax, amax)
                    if timed is not None:
                        plan, note, new = again, again.note, timed
                    elif again.stop or again.path is None or len(again.path) < 2:
                        # The planner's answer for the new goal: brake, or no
                        # motion (the current trajectory goes on).
                        plan, note = again, again.note
                        new = None
                        if again.stop and i is not None:
                            new = stopping_trajectory(current, i, vmax, amax)
                    # else: too short to stop on; the period's own plan stands.
            if not failed:
                faults.ok()
            # A period that compiled kernels (numba, at start-up) is not a miss.
            startup = compiles.count > compiled
            if startup:
                note = f"{note}; compiled kernels ({compute * 1e3:.0f} ms)".lstrip("; ")
            missed = (compute > period or timed_out) and not failed and not startup
            spliced = False
            if missed:
                why = note if timed_out else "result discarded"
                misses.missed(t, compute, period, why)
            else:
                misses.met(t)
                if new is not None:
                    sim.follow(current.splice(new))
                    if commanded is not None:
                        commanded(float(new.times[0]))
                    spliced = True
            next_period = adapter.next(t, period, compute, missed)
            run.log.periods.append(
                PeriodRecord(t, period, steps, compute, missed, spliced, note)
            )
            t, period = t_f, next_period
        misses.flush(t)
        if faults.aborted is None and not stop_requested():
            run.advance(run.duration)
        else:
            # Let the robot come to rest on the (stopping) trajectory it is on.
            run.advance(min(max(sim.trajectory.end_time, t) + 0.1, run.duration))
    finally:
        compiles.uninstall()
        try:
            planner.close()
        finally:
            trace = run.finish()
    return trace


#: A goal that arrives while the loop waits for its period's end is planned for
#: when at least this share of the shortest period is left (else it waits for
#: the next period, which starts by then).
REPLAN_SHARE = 0.2


def _plan_while_waiting(
    pacer: WallClockPacer,
    t: float,
    t_f: float,
    q_s: FloatArray,
    planner: Planner,
    run: RunParts,
    timing: ExecutorTiming,
    shortest: float,
    period: float,
) -> Plan | None:
    """A plan for a goal that arrived while the loop waited for its deadline.

    A live goal sets the pacer's wake event: the wait ends, and when at least
    :data:`REPLAN_SHARE` of the shortest period is left until ``t_f`` (a goal
    that came while the robot's motion was simulated finds the wait's event
    set), the planner plans again from the same start point toward the new
    goal, within the time left, so the goal is commanded at ``t_f`` and not a
    period later. The wait then
    goes on until ``t_f`` (again for a goal that arrives meanwhile). None when
    no goal arrived in time, and for a plan that ran out of time before it had
    a result (the period's own plan stands).
    """
    result: Plan | None = None
    while True:
        pacer.wait_until(t_f)
        left = pacer.left(t_f)
        if left <= 0:
            return result
        if not run.goal.changed() or left < REPLAN_SHARE * shortest:
            # Woken with too little time to plan: the goal waits for the
            # next period, which starts at t_f.
            pacer.wait_until(t_f, wakeable=False)
            return result
        budget = make_budget(
            timing.clock,
            timing.time_budget * left,
            timing.virtual_costs,
            horizon=period,
        )
        goal = run.goal.resend(t)
        with held(run.world):
            plan = planner.plan(q_s.copy(), goal, budget, run)
        if not plan.timed_out:
            result = plan


def stopping_trajectory(
    current: JointTrajectory, i: int, vmax: FloatArray, amax: FloatArray
) -> JointTrajectory | None:
    """Brake along ``current`` from its point ``i``, as soon as the limits allow.

    The path ahead was validated when it was planned; the shortest part of it
    from point ``i`` on which the robot can stop, timed by
    :func:`time_parameterize`, replaces the rest. None when the trajectory
    already stops no later than that (nothing to change).
    """
    t_s, _, v_s, a_s = current.point(i)
    ahead = current.positions[i:]
    # Binary search for the shortest prefix that can be stopped on (stoppable
    # prefixes are upward closed: a longer path leaves more room to brake). The
    # whole rest is not tried: when only it is stoppable, nothing changes.
    found: JointTrajectory | None = None
    lo, hi = 2, len(ahead)
    while lo < hi:
        mid = (lo + hi) // 2
        timed = time_parameterize(ahead[:mid], t_s, v_s, a_s, vmax, amax)
        if timed is None:
            lo = mid + 1
        else:
            hi, found = mid, timed
    return found
