# SPDX-License-Identifier: Apache-2.0
"""A simulated run, assembled in one place: :func:`build_run` and its parts.

The scenario is data (:mod:`cbp.scenario`); :func:`build_run` makes a run's
parts from it (the simulation, the collision world, the goal input, the
cameras and their map, the declared objects that move, the log and the fault
counter) as one frozen :class:`RunParts`, which the executors' loops drive.
Goal input (:mod:`.goal_input`), camera scheduling (:mod:`.cameras`), the
trace (:mod:`.recording`) and wall-clock pacing (:mod:`.pacing`) are modules
of their own.
"""

from cbp.run.events import RunLog
from cbp.run.faults import EXIT_ABORTED, MAX_FAULTS_IN_A_ROW, Faults
from cbp.run.goal_input import GoalInput
from cbp.run.pacing import WallClockPacer
from cbp.run.parts import RunParts, build_run

__all__ = [
    "EXIT_ABORTED",
    "MAX_FAULTS_IN_A_ROW",
    "Faults",
    "GoalInput",
    "RunLog",
    "RunParts",
    "WallClockPacer",
    "build_run",
]
