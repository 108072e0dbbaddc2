# SPDX-License-Identifier: Apache-2.0
"""The kinematic executor: each control step's QP displacement is applied exactly.

No simulator: the configuration is integrated with the QP's solution, one QP step
per control step of ``method.dt``. The goal stream is sampled at its own rate.
A goal that is NaN or malformed is ignored (the previous goal stays); a QP that
cannot be solved holds the robot still for that step. Both are recorded as events
and the loop goes on. So is anything else that raises in a step (a plugin, the
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
import pinocchio as pin

from cbp.errors import InvalidTargetError
from cbp.executors.stepping import Step, ValidatedStepper
from cbp.methods import METHODS
from cbp.methods.settings import KinematicSettings
from cbp.run.events import RunLog
from cbp.run.faults import Faults
from cbp.scenario.runtime import Scenario
from cbp.trace import Trace

__all__ = ["run_kinematic"]

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
    robot = scenario.robot
    engine = scenario.make_engine()
    stream = scenario.goal_stream()
    goal_task = scenario.goal_task()
    dt = scenario.spec.method.settings(KinematicSettings).dt
    steps = math.ceil(scenario.spec.duration / dt) + 1
    frame_id = robot.frame_id(scenario.ee_frame)
    q = scenario.q0.copy()
    run_log = RunLog("kinematic", scenario.spec.duration)
    t = 0.0
    world = scenario.world
    stepper = ValidatedStepper(engine, world, lambda m: run_log.event(t, m))
    faults = Faults(run_log.event)
    stepper.start(q)
    n = steps
    qs = np.empty((n, robot.nq))
    ee_p, ee_R = np.empty((n, 3)), np.empty((n, 3, 3))
    goal_p, goal_R = np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan)
    compute = np.empty(n)
    depth = np.zeros(n)
    rejected = 0
    goal: pin.SE3 | None = None
    change_time: float | None = None
    next_goal_time = 0.0
    for k in range(steps):
        t = k * dt
        start = time.perf_counter()
        try:
            if (
                stream is not None
                and goal_task is not None
                and t >= next_goal_time - 1e-9
            ):
                next_goal_time += stream.period
                candidate = stream.pose(t)
                try:
                    goal_task.set_target(candidate.translation, candidate.rotation)
                except InvalidTargetError as exc:
                    run_log.event(t, f"goal rejected, previous goal kept: {exc}")
                else:
                    if (
                        change_time is None
                        and goal is not None
                        and not goal.isApprox(candidate)
                    ):
                        change_time = t
                    goal = candidate
            step = stepper.step(q, dt)
        except Exception as exc:  # anything else: hold the robot, say so
            step = Step("failed", q, None, stepper.depth, "")
            faults.fault(t, "control step", exc)
            engine.state.update(q)  # the step may have failed before it did
        else:
            faults.ok()
        compute[k] = time.perf_counter() - start
        qs[k] = q
        # The engine's kinematics are those of q (the step's start).
        placement = engine.state.frame_placement(frame_id)
        ee_p[k] = placement.translation
        ee_R[k] = placement.rotation
        if goal is not None:
            goal_p[k] = goal.translation
            goal_R[k] = goal.rotation
        if step.outcome == "failed" and step.reason:
            run_log.event(t, f"step not solved, robot held: {step.reason}")
            log.warning("t=%.3f s: %s", t, step.reason)
        elif step.outcome == "rejected":
            rejected += 1
            run_log.event(t, f"step rejected: {step.reason}")
        depth[k] = stepper.depth
        q = step.q
        run_log.progress(t)
        if faults.aborted is not None:
            n = k + 1
            break
    return Trace(
        method="kinematic",
        t=np.arange(n, dtype=float) * dt,
        q=qs[:n],
        ee_position=ee_p[:n],
        ee_rotation=ee_R[:n],
        goal_position=goal_p[:n],
        goal_rotation=goal_R[:n],
        goal_change_time=change_time,
        q_names=robot.coordinate_names("q"),
        v_names=robot.coordinate_names("v"),
        events=run_log.events,
        compute_s=compute[:n],
        step_penetration=depth[:n] if world is not None else None,
        rejected_steps=rejected,
        aborted=faults.aborted,
    )
