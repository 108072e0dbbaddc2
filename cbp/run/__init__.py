# SPDX-License-Identifier: Apache-2.0
"""A simulated run: its parts (:func:`build_run`) and its one loop (:func:`run_loop`).

The scenario is data (:mod:`cbp.scenario`); :func:`build_run` binds a run's
parts from it (the simulation, the collision world, the goal input, the
cameras and their map, the declared objects that move, the log and the fault
counter) as one frozen :class:`RunParts`. :func:`run_loop` drives a
:class:`~cbp.run.plan.Planner` with them each command period, on a
:class:`LoopClock`; what it does is told to the listeners of the run's log
(:class:`RunListener`). Planning budgets (:mod:`.budget`), adaptive periods
(:mod:`.periods`), a live loop's wait (:mod:`.live`), leaving contact
(:mod:`.backout`), goal input (:mod:`.goal_input`), camera scheduling
(:mod:`.cameras`) and the trace (:mod:`.recording`) are modules of their own.
"""

from cbp.run.events import RunListener, RunLog, listening
from cbp.run.faults import EXIT_ABORTED, MAX_FAULTS_IN_A_ROW, Faults
from cbp.run.goal_input import GoalInput
from cbp.run.loop import Stepper, run_loop, run_ticks
from cbp.run.pacing import LoopClock, WallClockPacer
from cbp.run.parts import RunParts, build_run
from cbp.run.plan import Plan, Planner

__all__ = [
    "EXIT_ABORTED",
    "MAX_FAULTS_IN_A_ROW",
    "Faults",
    "GoalInput",
    "LoopClock",
    "Plan",
    "Planner",
    "RunListener",
    "RunLog",
    "RunParts",
    "Stepper",
    "WallClockPacer",
    "build_run",
    "listening",
    "run_loop",
    "run_ticks",
]
