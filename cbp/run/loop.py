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
   (:mod:`cbp.run.budget`).
4. The path is time-parameterized so that every joint can stop at its end
   within the velocity and acceleration limits (no inevitable collision state),
   and spliced in at that starting point with continuous position and velocity.
   A result computed after the deadline is discarded; so is one that cannot stop
   in time from the starting velocity (the current trajectory, which does stop,
   goes on).
5. The period adapts: longer after a miss, shorter when time was spare, but
   not below what the machine sustains (:mod:`cbp.run.periods`); misses
   are counted, not listed one by one.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Protocol

import numpy as np

from cbp.compilation import CompileCounter
from cbp.methods.settings import ExecutorTiming
from cbp.run.backout import BACK_OUT_DT, LeavingContact
from cbp.run.budget import make_budget
from cbp.run.events import RunLog
from cbp.run.faults import Faults
from cbp.run.live import COMMAND_LEAD, Waiting, advance_in_step, held, wait_out
from cbp.run.pacing import LoopClock
from cbp.run.parts import RunParts
from cbp.run.periods import DeadlineMisses, LeadAdapter, PeriodAdapter
from cbp.run.plan import Plan, Planner
from cbp.sim.trajectory import JointTrajectory, stopping_trajectory, time_parameterize
from cbp.trace import FORCED_OFF, PeriodRecord, Trace

__all__ = ["Stepper", "run_loop", "run_ticks"]


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
        off = np.abs(run.robot.difference(current.sample(t)[0], run.arm.q))
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


def run_loop(
    run: RunParts,
    planner: Planner,
    timing: ExecutorTiming,
    clock: LoopClock | None = None,
) -> Trace:
    """Run the scenario with ``planner`` each command period; return the trace.

    The one control loop of every method that plans per command period. A
    period in which something raises (the planner, the goal input, the
    simulator) holds the robot: it brakes along the trajectory it is on
    (:func:`~cbp.sim.trajectory.stopping_trajectory`), and the exception is
    an event. So does a period in which the run says the robot must hold
    (:meth:`RunParts.hold_reason`: a camera that gives no valid frames).
    After :data:`~cbp.run.faults.MAX_FAULTS_IN_A_ROW` failing periods the
    run is aborted: the robot stops, and the trace ends there with the reason.
    The planner is closed at the end. The run's log tells its listeners of
    each trajectory commanded and, live, of the robot's state as it moves
    (:class:`~cbp.run.events.RunListener`).

    Args:
        run: the run's parts (:func:`cbp.run.build_run`).
        planner: plans each period.
        timing: the command period, budget and limits.
        clock: how the loop keeps time (:class:`~cbp.run.pacing.LoopClock`);
            by default as fast as the work allows, and with cameras on the
            wall clock the world simulated no faster than the wall clock.
            Live, the loop plans a period, waits it out (commanding each goal
            that arrives meanwhile at once: :func:`~cbp.run.live.wait_out`),
            then simulates the robot's motion over it; unpaced, it simulates
            the motion while it plans, then commands the plan.
    """
    if clock is None:
        # A robot that runs on its own keeps the wall clock's pace itself.
        clock = LoopClock.unpaced(
            run.cameras is not None and run.clock == "wall" and run.arm.lockstep
        )
    pacer, world_pacer, stop_requested = clock.live, clock.world, clock.stop
    log = run.log
    shown = log.reached if log.listeners else None
    robot = run.robot
    vmax, amax = timing.limits(robot)
    lo, hi = timing.bounds()
    period = timing.period
    stop_time = robot.stopping_time(vmax, amax)
    t = 0.0
    sim = run.arm
    faults = run.faults
    adapter = PeriodAdapter(lo, hi, timing.growth, timing.shrink)
    leads = LeadAdapter(
        COMMAND_LEAD * lo, COMMAND_LEAD * hi, timing.growth, timing.shrink
    )
    leaving = LeavingContact(run, vmax * BACK_OUT_DT)
    forced = _ForcedOff(run)
    misses = DeadlineMisses(run.event)
    compiles = CompileCounter.install()
    # With cameras on the wall clock the map works beside the loop in real
    # time, so the simulated world must move in step with the wall clock too:
    # run as fast as the work allows, it raced ahead of the map whenever
    # plans came quickly (the map then read as lagging 0.5 s behind the
    # cameras and the robot was stopped while obstacles came on) and fell
    # behind it when they took their whole budget.
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
                clock.planning_time(timing.time_budget * period, t),
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
            seen: float | None = None
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
                    seen = run.seen()
                    with held(run):
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
                        advance_in_step(world_pacer, run, t_f, look_ahead, period)
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
                sim.follow(sim.trajectory.splice(new), source=seen)
                log.commanded(float(new.times[0]))
                spliced = True
            if pacer is not None:
                # Live: wait for t_f, commanding each goal that arrives
                # meanwhile at once; the robot's motion over the period is
                # simulated by then.
                answer = wait_out(
                    pacer,
                    Waiting(t, t_f, period, lo, leads, pending=moved),
                    planner,
                    run,
                    timing,
                    (vmax, amax),
                    look_ahead,
                    answer=not (failed or hold is not None or plan.final or plan.stop),
                    shown=shown,
                )
                steps += answer.steps
                note = answer.note if answer.note is not None else note
                spliced = spliced or answer.spliced
                failed = failed or answer.failed
                if shown is not None:
                    shown(t_f)
            if not failed:
                faults.ok()
            next_period = adapter.next(t, period, compute, missed)
            run.log.periods.append(
                PeriodRecord(t, period, steps, compute, missed, spliced, note)
            )
            # A robot that runs on its own did not wait for a late period.
            t = t_f if run.arm.lockstep else max(t_f, run.arm.t)
            period = next_period
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


class Stepper(Protocol):
    """A controller called once per control tick (kinematic, velocity, JT)."""

    def tick(self, t: float) -> None:
        """Control the tick at ``t`` [s] (its start; JT: its end); raise on failure."""
        ...

    def hold(self, t: float) -> None:
        """The tick at ``t`` failed: hold (brake) the robot."""
        ...


def _never() -> bool:
    return False


def run_ticks(
    stepper: Stepper,
    times: Iterable[float],
    log: RunLog,
    faults: Faults,
    what: str,
    stop: Callable[[], bool] = _never,
) -> None:
    """Drive ``stepper`` at each of ``times``: the tick loop of every stepper.

    A tick that raises holds the robot (:meth:`Stepper.hold`) and is a fault
    (``what`` names it in the event); after
    :data:`~cbp.run.faults.MAX_FAULTS_IN_A_ROW` in a row the run is aborted
    and the loop ends. Each tick's time is told to the log's listeners.
    """
    for t in times:
        if faults.aborted is not None or stop():
            return
        try:
            stepper.tick(t)
        except Exception as exc:  # any failure: hold the robot, say so
            faults.fault(t, what, exc)
            stepper.hold(t)
        else:
            faults.ok()
        log.progress(t)
