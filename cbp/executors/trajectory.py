# SPDX-License-Identifier: Apache-2.0
"""Trajectory executors: plan each command period, time it, splice it in.

The loop of CAT Sec. IV-D, shared by every method that sends joint trajectories
to the low-level follower (CAT, and the IK and MP methods):

1. At the start of a period (time t, length P) the operator's latest goal is
   taken. The deadline is t_f = t + P. In a live session, a goal that arrives
   after the planning ends the wait for t_f (the wall-clock pacer's wait ends
   on it): it is planned for at once, from the state the robot is commanded
   to be in a short lead later, and commanded then, not at t_f.
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
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np
import pinocchio as pin

from cbp.collision.world import CollisionWorld
from cbp.compilation import CompileCounter
from cbp.engine import Engine
from cbp.executors.backout import back_out
from cbp.executors.clock import Budget, make_budget
from cbp.executors.periods import DeadlineMisses, LeadAdapter, PeriodAdapter
from cbp.methods.settings import ExecutorTiming
from cbp.robot import FloatArray
from cbp.run.pacing import Pacer, WallClockPacer
from cbp.run.parts import RunParts, build_run
from cbp.scenario.runtime import Scenario
from cbp.sim.trajectory import JointTrajectory, time_parameterize
from cbp.state import RobotState
from cbp.trace import FORCED_OFF, PeriodRecord, Trace

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
        planner = make_planner(method, parts)
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
        self._state: RobotState | None = None  # one for every period's check

    def plan(self, t: float, q: FloatArray) -> Plan | None:
        """A back-out plan from ``q``, or None when the robot touches nothing."""
        world = self.run.world
        if world is None or world.environment.resolution > 0.0:
            return None
        if self._state is None or self._state.robot is not world.geometry.robot:
            self._state = RobotState(world.geometry.robot)
        path, depth = back_out(world, q, self.step_bound, self._state)
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


class _ForcedOff:
    """Says when something forces the arm off its command, and when it follows again.

    An arm pressed harder than its joints hold (an obstacle it cannot get
    away from; two that close on it) leaves its command; past that the
    contact forces are a crush's.
    """

    def __init__(self, run: RunParts) -> None:
        self.run = run
        self.since: float | None = None
        self._names = run.robot.coordinate_names("v")
        self._units = run.robot.coordinate_units("v")

    def check(self, t: float, current: JointTrajectory) -> None:
        """Compare the measured configuration with the command at ``t``."""
        run = self.run
        off = np.abs(run.robot.difference(current.sample(t)[0], run.sim.q))
        k = int(np.argmax(off))
        if self.since is None and off[k] > FORCED_OFF:
            self.since = t
            run.event(
                t,
                f"the arm is forced {off[k]:.2f} {self._units[k]} off its command "
                f"at {self._names[k]} by what it touches: pressed harder than its "
                "joints hold",
            )
        elif self.since is not None and off[k] <= 0.5 * FORCED_OFF:
            run.event(
                t, f"the arm follows its command again after {t - self.since:.2f} s"
            )
            self.since = None


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
    pacer: Pacer | None = None,
    stop_requested: Callable[[], bool] = _never,
    commanded: Callable[[float], None] | None = None,
    reached: Callable[[float], None] | None = None,
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
            None runs as fast as the work allows. Paced, the loop plans a
            period, waits it out (commanding each goal that arrives
            meanwhile at once: :func:`_command_while_waiting`), then
            simulates the robot's motion over it; unpaced, it simulates the
            motion while it plans, then commands the plan. An unpaced run
            with cameras on the wall clock simulates the world no faster
            than the wall clock all the same (:func:`_advance_in_step`).
        stop_requested: asked at each period's start; True ends the run
            there (an operator's stop).
        commanded: called with the start time of each trajectory spliced in.
        reached: called with the time up to which the robot's motion is
            simulated: each period's end, and paced, every
            :data:`SHOW_STEP` while the loop waits (the robot's state now,
            for a page that draws it).
    """
    robot = run.robot
    vmax, amax = timing.limits(robot)
    lo, hi = timing.bounds()
    period = timing.period
    stop_time = robot.stopping_time(vmax, amax)
    t = 0.0
    sim = run.sim
    faults = run.faults
    adapter = PeriodAdapter(lo, hi, timing.growth, timing.shrink)
    leads = LeadAdapter(
        COMMAND_LEAD * lo, COMMAND_LEAD * hi, timing.growth, timing.shrink
    )
    leaving = _LeavingContact(run, vmax * BACK_OUT_DT)
    forced = _ForcedOff(run)
    misses = DeadlineMisses(run.event)
    compiles = CompileCounter.install()
    # With cameras on the wall clock the map works beside the loop in real
    # time, so the simulated world must move in step with the wall clock too:
    # run as fast as the work allows, it raced ahead of the map whenever
    # plans came quickly (the map then read as lagging 0.5 s behind the
    # cameras and the robot was stopped while obstacles came on) and fell
    # behind it when they took their whole budget.
    world_pacer = (
        WallClockPacer()
        if pacer is None and run.cameras is not None and run.clock == "wall"
        else None
    )
    if world_pacer is not None:
        world_pacer.start(t)
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
            forced.check(t, current)
            budget = make_budget(
                timing.clock,
                _planning_time(timing.time_budget * period, pacer or world_pacer, t),
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
            # The latest goal accepted before this period's (a live goal that
            # arrives from now on is said new below).
            accepted = run.goal.changes
            taken = accepted[-1][1] if accepted else None
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
            if world_pacer is not None and t == 0.0 and compiles.count > compiled:
                # The world waits for the controller's start-up compilation
                # (numba, on a machine's first run): nothing has moved yet.
                # A world that then caught up at once handed the map a burst
                # of frames, and the map was behind its cameras (the robot
                # stopped) for the next two seconds.
                world_pacer.start(t)
            timed_out, steps = plan.timed_out, plan.steps
            # A live goal taken at the period's start or by the planner between
            # its steps (CAT) is commanded by this plan only after t_f.
            moved = taken is not None and accepted[-1][1] is not taken
            if pacer is None:
                try:
                    # The robot moves on while the result is computed.
                    if world_pacer is not None:
                        _advance_in_step(world_pacer, run, t_f, look_ahead, period)
                    else:
                        run.advance(t_f, look_ahead, reaction=2.0 * period)
                except Exception as exc:
                    failed = True
                    note = faults.fault(t, "simulation", exc)
            # A period that compiled kernels (numba, at start-up) is not a miss.
            startup = compiles.count > compiled
            if startup:
                note = f"{note}; compiled kernels ({compute * 1e3:.0f} ms)".lstrip("; ")
            missed = (compute > period or timed_out) and not failed and not startup
            spliced = False
            if missed and new is not None and not timed_out and i is None:
                # Late, but the robot holds at rest where the plan starts, and
                # nothing else was commanded meanwhile: the plan is as good when
                # it is ready, and is commanded from then (a look, a plan over
                # the wall: seconds of work a discard would throw away).
                ready = t + compute
                new = new.delayed(max(0.0, ready - new.start_time))
                misses.missed(t, compute, period, f"used from rest at {ready:.2f} s")
            elif missed:
                why = "result discarded" if new is not None and not timed_out else note
                misses.missed(t, compute, period, why)
                new = None
            else:
                misses.met(t)
            if new is not None:
                # Live, the simulation is not past t: new starts after t_f.
                sim.follow(sim.trajectory.splice(new))
                if commanded is not None:
                    commanded(float(new.times[0]))
                spliced = True
            if pacer is not None:
                # Live: wait for t_f, commanding each goal that arrives
                # meanwhile at once; the robot's motion over the period is
                # simulated by then.
                answer = _wait_out(
                    pacer,
                    Waiting(t, t_f, period, lo, leads, pending=moved),
                    planner,
                    run,
                    timing,
                    (vmax, amax),
                    commanded,
                    look_ahead,
                    answer=not (
                        failed or hold is not None or backing is not None or plan.stop
                    ),
                    shown=reached,
                )
                steps += answer.steps
                note = answer.note if answer.note is not None else note
                spliced = spliced or answer.spliced
                failed = failed or answer.failed
                if reached is not None:
                    reached(t_f)
            if not failed:
                faults.ok()
            next_period = adapter.next(t, period, compute, missed)
            run.log.periods.append(
                PeriodRecord(t, period, steps, compute, missed, spliced, note)
            )
            t, period = t_f, next_period
        misses.flush(t)
        if faults.aborted is None and not stop_requested():
            run.advance(run.duration)
        else:
            # Brake, and let the robot come to rest on that trajectory.
            current = sim.trajectory
            i = current.first_point_after(t)
            braking = (
                stopping_trajectory(current, i, vmax, amax) if i is not None else None
            )
            if braking is not None:
                sim.follow(current.splice(braking))
            run.advance(min(max(sim.trajectory.end_time, t) + 0.1, run.duration))
    finally:
        compiles.uninstall()
        try:
            planner.close()
        finally:
            trace = run.finish()
    return trace


#: The least share of its planning budget a period keeps when the simulated
#: world is behind the wall clock (:func:`_planning_time`).
MIN_BUDGET_SHARE = 0.25


def _planning_time(budget: float, pacer: Pacer | None, t: float) -> float:
    """A period's planning budget [s]: ``budget``, less how late the period starts.

    On the wall clock the simulated world and the cameras take their share
    of the same core after the plan; a period that starts behind the wall
    clock (``pacer``) plans that much less, down to :data:`MIN_BUDGET_SHARE`
    of ``budget``, so the world catches up instead of falling further
    behind. Measured on the generated scene moving_11 with the cameras (the
    map in its own process, load 1): planning took up to 85 % of each
    period and simulating the world and rendering its cameras 35 %, so the
    world fell 0.4 s behind the wall clock in 3 s and caught up in a burst
    once the plans came quickly.
    """
    if pacer is None:
        return budget
    late = -pacer.left(t)
    if late <= 0.0:
        return budget
    return max(MIN_BUDGET_SHARE * budget, budget - late)


def _advance_in_step(
    pacer: Pacer, run: RunParts, t_f: float, look_ahead: float, period: float
) -> None:
    """Simulate the world up to ``t_f``, no faster than the wall clock.

    As a live loop's wait does (:class:`_Showing`): up to now every
    :data:`SHOW_STEP` (the cameras capture their frames about when the wall
    clock reaches their capture times, as the map beside the loop sees
    them), then the rest at ``t_f``; a world behind the wall clock catches
    up at once.
    """
    _Showing(pacer, run, 2.0 * period, look_ahead, _simulated).until(
        t_f, wakeable=False
    )
    run.advance(t_f, look_ahead, reaction=2.0 * period)


def _simulated(t: float) -> None:
    """Nothing to show: an unpaced run's world only keeps the clock's pace."""


#: A goal that arrives while the loop waits for its period's end is planned
#: for within a lead and commanded at the lead's end, from the state the
#: robot is commanded to be in then. The lead is this share of the shortest
#: period to start with, longer after plans made too late
#: (:class:`~cbp.executors.periods.LeadAdapter`, up to this share of the
#: longest period).
COMMAND_LEAD = 0.4
#: ... when at least this share of the shortest period is left before the
#: period's end (else it waits for the next period, which starts by then).
REPLAN_SHARE = 0.2
#: While a live loop waits out its period, the robot's motion is simulated up
#: to now and shown (``reached``) this often [s]: a page sees the arm move
#: within this, not only at the period's end.
SHOW_STEP = 0.005


class Waiting(NamedTuple):
    """The period a live loop waits out: from ``t`` to ``t_f`` [s].

    Attributes:
        t: the period's start.
        t_f: its end (the deadline).
        period: its length.
        shortest: the shortest period.
        leads: the lead of a plan for a goal that arrives meanwhile.
        pending: a goal newer than the period's arrived while its plan was
            made (and was taken by the planner): plan for it at once.
    """

    t: float
    t_f: float
    period: float
    shortest: float
    leads: LeadAdapter
    pending: bool = False


class WaitAnswer(NamedTuple):
    """What the goals that arrived during a wait were given.

    Attributes:
        steps: planning steps taken for them.
        note: the last plan's note (None: no plan was made).
        spliced: whether a trajectory planned for one was commanded.
        failed: whether planning or simulating failed (an event said so).
    """

    steps: int
    note: str | None
    spliced: bool
    failed: bool = False


def _wait_out(
    pacer: Pacer,
    waiting: Waiting,
    planner: Planner,
    run: RunParts,
    timing: ExecutorTiming,
    limits: tuple[FloatArray, FloatArray],
    commanded: Callable[[float], None] | None,
    look_ahead: float,
    answer: bool,
    shown: Callable[[float], None] | None = None,
) -> WaitAnswer:
    """A live period after its plan: simulate, wait out, answer new goals.

    The robot's motion is simulated at most a lead (:data:`COMMAND_LEAD`)
    ahead of now before the wait, up to now during it (every
    :data:`SHOW_STEP`, each time told to ``shown``), the rest after it, so a
    goal that arrives during the
    wait can be commanded a lead after it (:func:`_command_while_waiting`;
    only when ``answer``: not while the robot holds, brakes or backs out). A
    failure to plan brakes the robot; a failure to simulate is a fault of the
    period, as in an unpaced run.
    """
    t, t_f, period = waiting.t, waiting.t_f, waiting.period
    faults = run.faults
    now = t_f - pacer.left(t_f)
    try:
        run.advance(
            min(t_f, now + waiting.leads.lead),
            look_ahead,
            reaction=2.0 * period,
        )
    except Exception as exc:
        note = faults.fault(t, "simulation", exc)
        pacer.wait_until(t_f, wakeable=False)
        return WaitAnswer(0, note, False, failed=True)
    wait = _Showing(pacer, run, 2.0 * period, look_ahead, shown)
    result = WaitAnswer(0, None, False)
    if not answer:
        wait.until(t_f, wakeable=False)
    else:
        try:
            result = _command_while_waiting(
                wait, waiting, planner, run, timing, *limits, commanded
            )
        except Exception as exc:  # as a failing period: hold the robot
            note = faults.fault(t, "planning", exc)
            _brake_after(run, t_f, *limits)
            pacer.wait_until(t_f, wakeable=False)
            result = WaitAnswer(0, note, False, failed=True)
    try:
        run.advance(t_f, look_ahead, reaction=2.0 * period)
    except Exception as exc:
        note = faults.fault(t, "simulation", exc)
        return WaitAnswer(result.steps, note, result.spliced, failed=True)
    return result


class _Showing:
    """A live loop's wait that simulates the robot up to now as it goes.

    Each :data:`SHOW_STEP` of the wait the robot's motion is simulated up to
    now, once now is past the lead simulated before the wait, and ``shown``
    is told: a page shows the robot's state once the wall clock has reached
    it, so it is not simulated ahead here. A failure to simulate ends that:
    the period's last step simulates the rest and reports it.
    """

    def __init__(
        self,
        pacer: Pacer,
        run: RunParts,
        reaction: float,
        look_ahead: float,
        shown: Callable[[float], None] | None,
    ) -> None:
        """The loop's pacer and parts; ``reaction``: the executor's [s]."""
        self.pacer, self.run, self.reaction = pacer, run, reaction
        self.look_ahead, self.shown = look_ahead, shown
        self._failed = False

    def left(self, t: float) -> float:
        """How long until the loop's time ``t`` is now [s]."""
        return self.pacer.left(t)

    def until(self, t_f: float, wakeable: bool = True) -> None:
        """Wait until ``t_f`` (or a wake, when ``wakeable``), showing the robot."""
        pacer = self.pacer
        while True:
            left = pacer.left(t_f)
            if left <= 0:
                return
            showing = self.shown is not None and not self._failed
            step = min(t_f, t_f - left + SHOW_STEP) if showing else t_f
            pacer.wait_until(step, wakeable)
            if wakeable and pacer.left(step) > 1e-9:
                return  # woken: a new goal
            if step >= t_f or self.shown is None or self._failed:
                continue
            sim = self.run.sim
            now = min(t_f, t_f - pacer.left(t_f))
            if now <= sim.t:
                continue  # still within the lead simulated before the wait
            try:
                self.run.advance(now, self.look_ahead, reaction=self.reaction)
            except Exception:
                self._failed = True  # the period's end simulates it, and says so
                continue
            self.shown(sim.t)


def _command_while_waiting(
    pacer: _Showing,
    waiting: Waiting,
    planner: Planner,
    run: RunParts,
    timing: ExecutorTiming,
    vmax: FloatArray,
    amax: FloatArray,
    commanded: Callable[[float], None] | None,
) -> WaitAnswer:
    """Wait until ``waiting.t_f``; plan for and command each goal that arrives.

    A live goal sets the pacer's wake event: the wait ends at the loop's time
    ``now``. The splice time is ``t_c = now + lead``, the lead being
    :class:`~cbp.executors.periods.LeadAdapter`'s (or the time left, if less); the
    planner plans from the state the current trajectory commands at ``t_c``
    (position, velocity, acceleration) toward the new goal, within
    ``timing.time_budget`` of the lead, and a result made within the lead is
    timed from that state and spliced in at ``t_c``: the goal is commanded
    as soon as it is planned for, not at the period's end. The simulation
    has not run past the period's start (the loop simulates a period after
    waiting it out), so the robot has not yet passed ``t_c``. A result made
    after ``t_c`` is made again from a later start with a longer lead, while
    the time left allows (then the next period takes the goal); one too short
    to stop on is dropped (the current trajectory goes on); a plan that says
    stop brakes along the current trajectory from ``t_c`` on. With less than
    :data:`REPLAN_SHARE` of the shortest period left, the goal waits for the
    next period. The wait goes on until ``t_f``. A goal that the period's
    planner took between its steps (``waiting.pending``) is planned for so
    at once, without waiting: the period's plan commands it only after
    ``t_f``.
    """
    t_f = waiting.t_f
    steps, note, spliced, late = 0, None, False, 0
    sim = run.sim
    fresh = waiting.pending
    while True:
        if not fresh:
            pacer.until(t_f)
            fresh = run.goal.changed()
        left = pacer.left(t_f)
        if left > 0 and (not fresh or left < REPLAN_SHARE * waiting.shortest):
            pacer.until(t_f, wakeable=False)
            left = 0.0
        if left <= 0:
            if late:
                note = f"{note}; {late} plan(s) made after their lead".lstrip("; ")
            return WaitAnswer(steps, note, spliced)
        fresh = False
        now = t_f - left
        # Not before the simulated robot's time (it is at most a lead ahead).
        t_c = max(now + min(waiting.leads.lead, left), sim.t)
        lead = t_c - now
        current = sim.trajectory
        q_c, v_c, a_c = current.sample(t_c)
        # Followed until the next period's plan replaces it (a period after t_f).
        budget = make_budget(
            timing.clock,
            timing.time_budget * lead,
            timing.virtual_costs,
            horizon=t_f + waiting.period - t_c,
        )
        goal = run.goal.resend(t_c)
        with held(run.world):
            plan = planner.plan(q_c.copy(), goal, budget, run)
        steps += plan.steps
        note = plan.note
        new: JointTrajectory | None = None
        if plan.path is not None and len(plan.path) > 1:
            new = time_parameterize(plan.path, t_c, v_c, a_c, vmax, amax)
            budget.charge("trajectory_point", len(plan.path))
            if new is None:
                note = "path too short to stop on; current trajectory kept"
        elif plan.stop:  # brake (an operator's pause): at once, whenever planned
            _brake_after(run, t_c, vmax, amax)
        in_time = not plan.timed_out and budget.elapsed() <= lead
        before = waiting.leads.lead
        waiting.leads.planned(in_time)
        if not in_time:
            # Made again from a later start, with a longer lead (if it could
            # grow, and time is left).
            late += 1
            fresh = not plan.stop and waiting.leads.lead > before
            continue
        if new is not None:
            sim.follow(current.splice(new))
            if commanded is not None:
                commanded(t_c)
            spliced = True


def _brake_after(run: RunParts, t: float, vmax: FloatArray, amax: FloatArray) -> None:
    """Brake along the trajectory the robot follows from its first point after ``t``."""
    sim = run.sim
    current = sim.trajectory
    i = current.first_point_after(t)
    if i is None:
        return
    stopping = stopping_trajectory(current, i, vmax, amax)
    if stopping is not None:
        sim.follow(current.splice(stopping))


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
