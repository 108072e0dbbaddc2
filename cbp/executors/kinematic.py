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
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from cbp.errors import InvalidTargetError, PluginOutputError, SolveError
from cbp.robot import FloatArray
from cbp.scenario import Scenario

log = logging.getLogger(__name__)


@dataclass
class Trace:
    """What a run recorded, one row per control step.

    Attributes:
        t: times [s] (N,).
        q: configurations (N, nq).
        ee_position: end-effector position (N, 3) [m].
        goal_position: goal position (N, 3) [m], NaN without a goal.
        position_error: end-effector to goal distance (N,) [m].
        rotation_error: rotation angle between end effector and goal (N,) [rad].
        solve_time: engine step wall time (N,) [s].
        events: (time, message) for every goal rejected or step not solved.
        joint_names: names of the model's joints.
        penetration: deepest penetration of the padded links at each step (N,)
            [m]; empty without a collision world.
        rejected_steps: steps rejected by step validation.
    """

    t: FloatArray
    q: FloatArray
    ee_position: FloatArray
    goal_position: FloatArray
    position_error: FloatArray
    rotation_error: FloatArray
    solve_time: FloatArray
    events: list[tuple[float, str]] = field(default_factory=list)
    joint_names: list[str] = field(default_factory=list)
    penetration: FloatArray = field(default_factory=lambda: np.zeros(0))
    rejected_steps: int = 0


def run_kinematic(scenario: Scenario) -> Trace:
    """Run the scenario for its duration and return the trace."""
    robot = scenario.robot
    engine = scenario.make_engine()
    stream = scenario.goal_stream()
    goal_task = scenario.goal_task()
    dt = scenario.spec.method.dt
    steps = math.ceil(scenario.spec.duration / dt) + 1
    ee_frame = robot.frame_id(
        robot.description.end_effector if robot.description else robot.frame_names[-1]
    )
    frame_id = getattr(goal_task, "frame_id", ee_frame)
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
                goal_task.set_target(candidate.translation, candidate.rotation)  # type: ignore[attr-defined]
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
            check = world.check(q_next)
            if not check.accepted:
                depth.append(depth[-1] if depth else 0.0)  # the robot stays
                rejected += 1
                world.reject(check)
                events.append(
                    (t, f"step rejected: penetration {check.penetration * 1e3:.1f} mm")
                )
                continue
            depth.append(check.penetration)
        q = q_next
    return Trace(
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
