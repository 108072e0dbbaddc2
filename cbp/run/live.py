# SPDX-License-Identifier: Apache-2.0
"""A live loop's wait: simulate the period, show the robot, answer new goals.

Paced on the wall clock (:class:`~cbp.run.pacing.LoopClock` ``live``), the
loop (:mod:`cbp.run.loop`) plans a period and then waits it out here: the
robot's motion is simulated up to now as the wall clock goes (shown to the
run's listeners every :data:`SHOW_STEP`), and a goal that arrives meanwhile
is planned for and commanded a lead after it arrives, not at the period's end.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import NamedTuple

from cbp.methods.settings import ExecutorTiming
from cbp.robot import FloatArray
from cbp.run.budget import make_budget
from cbp.run.pacing import Pacer
from cbp.run.parts import RunParts
from cbp.run.periods import LeadAdapter
from cbp.run.plan import Planner
from cbp.sim.trajectory import JointTrajectory, stopping_trajectory, time_parameterize

__all__ = [
    "COMMAND_LEAD",
    "REPLAN_SHARE",
    "SHOW_STEP",
    "WaitAnswer",
    "Waiting",
    "advance_in_step",
    "held",
    "wait_out",
]


def held(run: RunParts) -> contextlib.AbstractContextManager[object]:
    """The world's snapshot held while a plan is made (nothing without a world)."""
    world = run.world
    return contextlib.nullcontext() if world is None else world.holding()


def advance_in_step(
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
#: (:class:`~cbp.run.periods.LeadAdapter`, up to this share of the
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


def wait_out(
    pacer: Pacer,
    waiting: Waiting,
    planner: Planner,
    run: RunParts,
    timing: ExecutorTiming,
    limits: tuple[FloatArray, FloatArray],
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
                wait, waiting, planner, run, timing, *limits
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
            sim = self.run.arm
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
) -> WaitAnswer:
    """Wait until ``waiting.t_f``; plan for and command each goal that arrives.

    A live goal sets the pacer's wake event: the wait ends at the loop's time
    ``now``. The splice time is ``t_c = now + lead``, the lead being
    :class:`~cbp.run.periods.LeadAdapter`'s (or the time left, if less); the
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
    sim = run.arm
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
        with held(run):
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
            run.log.commanded(t_c)
            spliced = True


def _brake_after(run: RunParts, t: float, vmax: FloatArray, amax: FloatArray) -> None:
    """Brake along the trajectory the robot follows from its first point after ``t``."""
    sim = run.arm
    current = sim.trajectory
    i = current.first_point_after(t)
    if i is None:
        return
    stopping = stopping_trajectory(current, i, vmax, amax)
    if stopping is not None:
        sim.follow(current.splice(stopping))
