# SPDX-License-Identifier: Apache-2.0
"""The kinematic executor: each control step's QP displacement is applied exactly.

No simulator: the configuration is integrated with the QP's solution, one QP step
per control step of ``method.dt``, driven by the run layer's tick loop
(:func:`~cbp.run.loop.run_ticks`). The goal is taken as every method takes
it (:class:`~cbp.run.goal_input.GoalInput`): sampled at its source's rate, a
NaN or malformed goal ignored (the previous goal stays). A QP that cannot be
solved holds the robot still for that step. Both are recorded as events and
the loop goes on. So is anything else that raises in a step (a plugin, the
collision world); after :data:`~cbp.run.faults.MAX_FAULTS_IN_A_ROW` such
steps in a row the run is aborted and the trace ends there.

When the scenario has contact constraints, every step is validated (CAT Sec.
IV-C): the new configuration is collision-checked, and a step that penetrates
deeper than ``collision.penetration_tolerance`` is rejected. The robot stays, and
the contacts found at the rejected configuration constrain the retried step.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from cbp.executors.stepping import Step, ValidatedStepper
from cbp.methods import METHODS
from cbp.methods.settings import KinematicSettings
from cbp.robot import FloatArray
from cbp.run.events import RunLog
from cbp.run.faults import Faults
from cbp.run.goal_input import GoalInput
from cbp.run.loop import run_ticks
from cbp.scenario.runtime import Scenario
from cbp.trace import Trace

__all__ = ["KinematicStepper", "run_kinematic"]

log = logging.getLogger(__name__)


def run_kinematic(scenario: Scenario, gui: bool = False) -> Trace:
    """Run the scenario for its duration and return the trace.

    There is no simulator, so ``gui`` has nothing to show.

    Raises:
        ConfigError: the scenario asks for the depth cameras (none here).
    """
    METHODS["kinematic"].refuse_source(
        scenario.spec.perception.source, f"{scenario.path}: perception.source"
    )
    scenario = scenario.bound()  # this run's own plugins and world
    run_log = RunLog("kinematic", scenario.spec.duration)
    faults = Faults(run_log.event)
    stepper = KinematicStepper(scenario, run_log)
    dt = stepper.dt
    times = np.arange(math.ceil(scenario.spec.duration / dt) + 1) * dt
    run_ticks(stepper, times, run_log, faults, "control step")
    return stepper.trace(faults.aborted)


class KinematicStepper:
    """One validated QP step per tick, integrated exactly; the samples kept.

    Args:
        scenario: the run's binding of the scenario.
        run_log: the run's log (events).
    """

    def __init__(self, scenario: Scenario, run_log: RunLog) -> None:
        """Start at the scenario's initial configuration."""
        self.scenario, self.log = scenario, run_log
        self.robot = robot = scenario.robot
        self.dt = scenario.spec.method.settings(KinematicSettings).dt
        self.engine = scenario.make_engine()
        self.goal = GoalInput(
            scenario.goal_stream(),
            scenario.goal_task(),
            run_log,
            reach=scenario.reach(),
        )
        self.q = scenario.q0.copy()
        self.t = 0.0
        self.stepper = ValidatedStepper(
            self.engine, scenario.world, run_log.event, lambda: self.t
        )
        self.stepper.start(self.q)
        self.frame_id = robot.frame_id(scenario.ee_frame)
        self.rows: dict[str, list[FloatArray]] = {
            k: [] for k in ("t", "q", "ee_p", "ee_R", "compute", "depth")
        }
        self.rejected = 0
        self._start = 0.0

    def tick(self, t: float) -> None:
        """Take the goal at ``t``, step, record the sample at the step's start."""
        self.t = t
        self._start = time.perf_counter()
        self.goal.send(t)
        step = self.stepper.step(self.q, self.dt)
        if step.outcome == "failed" and step.reason:
            self.log.event(t, f"step not solved, robot held: {step.reason}")
            log.warning("t=%.3f s: %s", t, step.reason)
        elif step.outcome == "rejected":
            self.rejected += 1
            self.log.event(t, f"step rejected: {step.reason}")
        self._record(t, step)

    def hold(self, t: float) -> None:
        """The step raised: the robot stays where it is."""
        self.engine.state.update(self.q)  # the step may have failed before it did
        self._record(t, Step("failed", self.q, None, self.stepper.depth, ""))

    def _record(self, t: float, step: Step) -> None:
        rows = self.rows
        rows["compute"].append(np.array(time.perf_counter() - self._start))
        rows["t"].append(np.array(t))
        rows["q"].append(self.q)
        # The engine's kinematics are those of q (the step's start).
        placement = self.engine.state.frame_placement(self.frame_id)
        rows["ee_p"].append(placement.translation.copy())
        rows["ee_R"].append(placement.rotation.copy())
        rows["depth"].append(np.array(self.stepper.depth))
        self.q = step.q

    def trace(self, aborted: str | None) -> Trace:
        """The samples so far as a trace (``aborted``: why the run ended early)."""
        self.stepper.eased.flush()
        robot, rows = self.robot, self.rows
        n = len(rows["t"])
        t = np.array(rows["t"], dtype=float).reshape(n)
        goal_p, goal_R = np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan)
        changes = self.goal.changes
        times = np.array([c[0] for c in changes])
        for i in range(n):
            k = int(np.searchsorted(times, t[i] + 1e-9)) - 1
            if k >= 0:
                goal_p[i] = changes[k][1].translation
                goal_R[i] = changes[k][1].rotation
        return Trace(
            method="kinematic",
            t=t,
            q=np.array(rows["q"], dtype=float).reshape(n, robot.nq),
            ee_position=np.array(rows["ee_p"], dtype=float).reshape(n, 3),
            ee_rotation=np.array(rows["ee_R"], dtype=float).reshape(n, 3, 3),
            goal_position=goal_p,
            goal_rotation=goal_R,
            goal_change_time=float(times[1]) if times.size > 1 else None,
            q_names=robot.coordinate_names("q"),
            v_names=robot.coordinate_names("v"),
            events=self.log.events,
            compute_s=np.array(rows["compute"], dtype=float).reshape(n),
            step_penetration=(
                np.array(rows["depth"], dtype=float).reshape(n)
                if self.scenario.world is not None
                else None
            ),
            rejected_steps=self.rejected,
            aborted=aborted,
        )
