# SPDX-License-Identifier: Apache-2.0
"""The kinematic executor: each control step's QP displacement is applied exactly.

No simulator: the configuration is integrated with the QP's solution, one QP step
per control step of ``method.dt``. The goal stream is sampled at its own rate.
A goal that is NaN or malformed is ignored (the previous goal stays); a QP that
cannot be solved holds the robot still for that step. Both are recorded as events
and the loop goes on.

When the scenario has contact constraints, every step is validated (CAT Sec.
IV-C): the new configuration is collision-checked, and a step that penetrates
deeper than ``collision.penetration_tolerance`` is rejected. The robot stays, and
the contacts found at the rejected configuration constrain the retried step.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from cbp.errors import InvalidTargetError, PluginOutputError, SolveError
from cbp.executors import single_run
from cbp.executors.settings import KinematicSettings
from cbp.report import write_outputs
from cbp.scenario.runtime import Scenario
from cbp.trace import KinematicTrace

log = logging.getLogger(__name__)


def run_kinematic(scenario: Scenario) -> KinematicTrace:
    """Run the scenario for its duration and return the trace."""
    robot = scenario.robot
    engine = scenario.make_engine()
    stream = scenario.goal_stream()
    goal_task = scenario.goal_task()
    dt = scenario.spec.method.settings(KinematicSettings).dt
    steps = math.ceil(scenario.spec.duration / dt) + 1
    frame_id = robot.frame_id(scenario.ee_frame)
    q = scenario.q0.copy()
    rows: dict[str, list[object]] = {
        k: [] for k in ("t", "q", "ee", "goal", "perr", "rerr", "time")
    }
    events: list[tuple[float, str]] = []
    world = scenario.collision_world() if scenario.needs_collision_world else None
    depth: list[float] = []
    rejected = 0
    goal: pin.SE3 | None = None
    next_goal_time = 0.0
    for k in range(steps):
        t = k * dt
        if stream is not None and goal_task is not None and t >= next_goal_time - 1e-9:
            next_goal_time += stream.period
            candidate = stream.pose(t)
            try:
                goal_task.set_target(candidate.translation, candidate.rotation)
                goal = candidate
            except InvalidTargetError as exc:
                events.append((t, f"goal rejected, previous goal kept: {exc}"))
        start = time.perf_counter()
        try:
            dq = engine.step(q, dt)
        except (SolveError, PluginOutputError) as exc:
            dq = np.zeros(robot.nv)
            events.append((t, f"step not solved, robot held: {exc}"))
            log.warning("t=%.3f s: %s", t, exc)
        else:
            if engine.recovery_changed and engine.recovery is not None:
                events.append((t, f"QP eased: {engine.recovery}"))
        elapsed = time.perf_counter() - start
        placement = engine.state.frame_placement(frame_id)
        rows["t"].append(t)
        rows["q"].append(q.copy())
        rows["ee"].append(np.array(placement.translation))
        rows["time"].append(elapsed)
        if goal is not None:
            rows["goal"].append(np.array(goal.translation))
            rows["perr"].append(
                float(np.linalg.norm(placement.translation - goal.translation))
            )
            rows["rerr"].append(
                float(np.linalg.norm(pin.log3(placement.rotation.T.dot(goal.rotation))))
            )
        else:
            rows["goal"].append(np.full(3, np.nan))
            rows["perr"].append(np.nan)
            rows["rerr"].append(np.nan)
        q_next = robot.integrate(q, dq)
        if world is not None:
            check = world.try_step(q_next)
            if not check.accepted:
                depth.append(depth[-1] if depth else 0.0)  # the robot stays
                rejected += 1
                events.append(
                    (t, f"step rejected: penetration {check.penetration * 1e3:.1f} mm")
                )
                continue
            depth.append(check.penetration)
        q = q_next
    return KinematicTrace(
        t=np.array(rows["t"], dtype=float),
        q=np.array(rows["q"], dtype=float),
        ee_position=np.array(rows["ee"], dtype=float),
        goal_position=np.array(rows["goal"], dtype=float),
        position_error=np.array(rows["perr"], dtype=float),
        rotation_error=np.array(rows["rerr"], dtype=float),
        solve_time=np.array(rows["time"], dtype=float),
        events=events,
        joint_names=robot.joint_names,
        penetration=np.array(depth, dtype=float),
        rejected_steps=rejected,
    )


class KinematicExecutor:
    """The kinematic executor's entry in the executor table."""

    def run(self, scenario: Scenario, gui: bool = False) -> KinematicTrace:
        """Run ``scenario`` (there is no simulator window to show)."""
        return run_kinematic(scenario)

    def write(
        self, scenario: Scenario, traces: Mapping[str, Any], out: Path
    ) -> dict[str, dict[str, Any]]:
        """trace.csv, metrics.json, tracking.png and report.md (one run)."""
        method, trace = single_run(traces, "kinematic")
        return {method: write_outputs(scenario, trace, out)}

    def describe(
        self, scenario: Scenario, method: str, metrics: Mapping[str, Any]
    ) -> str:
        """Steps, final error, events."""
        return (
            f"{scenario.spec.name}: {metrics['steps']} steps, final position error "
            f"{metrics['final_position_error_m']} m, {metrics['events']} events"
        )


EXECUTOR = KinematicExecutor()
