# SPDX-License-Identifier: Apache-2.0
"""The velocity executor: one QP per control tick, velocities to the robot.

For mobile manipulators driven by velocity (the orbit paper's Problem 4.3): each
tick of ``method.velocity.dt`` the operator's inputs (functions of time, the
scenario's ``inputs:``) are handed to their entries, the engine solves the QP
from the measured configuration, and ``u = dq / dt`` (base v_x, v_y, yaw rate,
then the arm's joints) is sent to the simulator. Orbit object and pan object are
configurations (``scenarios/youbot_*.yaml``), not code here.

Each step is given the last command as the robot's velocity: the engine's step
guard refuses a command that changes a joint's velocity faster than its
acceleration limit, and a ``joint_acceleration`` constraint (in
``configs/orbit.yaml``) keeps the QP's answers within it. A bad input value is
refused (the entry keeps its previous one); a QP that cannot be solved, or an
answer the guard refuses, brakes the robot for that tick within its
acceleration limits. Both are events, and the loop goes on.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

import numpy as np

from cbp.errors import PluginOutputError, SolveError
from cbp.executors.faults import Faults
from cbp.executors.settings import VelocitySettings
from cbp.plugin import ReportsSignals
from cbp.progress import report_time
from cbp.robot import FloatArray
from cbp.scenario.runtime import Scenario
from cbp.sim.mobile import MobileSimulation
from cbp.state import RobotState
from cbp.trace import Trace

__all__ = ["run_velocity"]

log = logging.getLogger(__name__)


def run_velocity(scenario: Scenario, gui: bool = False) -> Trace:
    """Run ``scenario`` with the velocity executor; return the trace."""
    robot = scenario.robot
    engine = scenario.make_engine()
    inputs = scenario.inputs()
    names = {id(e.plugin): e.name for e in scenario.entries}
    settings = scenario.spec.method.settings(VelocitySettings)
    dt = settings.dt
    steps = math.ceil(scenario.spec.duration / dt)
    rows: dict[str, list[Any]] = {
        k: [] for k in ("t", "q", "u", "time", "ee_p", "ee_R")
    }
    frame_id = robot.frame_id(scenario.ee_frame)
    values: dict[str, list[FloatArray]] = {names[id(p)]: [] for p, _ in inputs}
    events: list[tuple[float, str]] = []
    failing = 0
    reporters = [
        e.plugin for e in scenario.entries if isinstance(e.plugin, ReportsSignals)
    ]
    signals: dict[str, list[float]] = {}
    state = RobotState(robot)
    sim = MobileSimulation(
        robot,
        scenario.spec.world.objects,
        scenario.q0,
        scenario.spec.simulation,
        scenario.path.parent,
        gui,
    )
    faults = Faults(lambda at, m: events.append((at, m)))
    if not any(e.plugin.type_name == "joint_acceleration" for e in scenario.entries):
        events.append(
            (
                0.0,
                "no joint_acceleration constraint: answers that accelerate past "
                "the limits are refused and the robot brakes",
            )
        )
    braking = robot.acceleration_limits * dt
    u = np.zeros(robot.nv)  # the last command: the robot starts at rest
    try:
        for k in range(steps):
            t = k * dt
            for plugin, functions in inputs:
                name = names[id(plugin)]
                try:
                    value = np.array([f(t) for f in functions])
                    plugin.set_input(value)
                except (ValueError, ArithmeticError) as exc:
                    value = np.full(len(functions), np.nan)
                    events.append((t, f"input to '{name}' refused: {exc}"))
                values[name].append(value)
            q = sim.q
            start = time.perf_counter()
            try:
                dq = engine.step(q, dt, u)
            except (SolveError, PluginOutputError) as exc:
                dq = _brake(u, braking) * dt
                failing += 1
                if failing == 1:  # one event per run of failed ticks
                    events.append((t, f"step not solved, robot braking: {exc}"))
                    log.warning("t=%.3f s: %s", t, exc)
            except Exception as exc:  # anything else: brake the robot, count it
                dq = _brake(u, braking) * dt
                faults.fault(t, "control step", exc)
            else:
                faults.ok()
                if failing:
                    events.append((t, f"solved again after {failing} failed ticks"))
                failing = 0
                if engine.recovery_changed and engine.recovery is not None:
                    events.append((t, f"QP eased: {engine.recovery}"))
            elapsed = time.perf_counter() - start
            # The end effector, and what the plugins report, at the tick's
            # measured configuration and with the inputs in effect.
            state.update(q)
            placement = state.frame_placement(frame_id)
            rows["ee_p"].append(placement.translation.copy())
            rows["ee_R"].append(placement.rotation.copy())
            for reporter in reporters:
                try:
                    reported = reporter.signals(state)
                except Exception as exc:  # a report is not worth stopping for
                    faults.fault(t, "signal report", exc)
                    continue
                for key, signal in reported.items():
                    signals.setdefault(key, []).append(signal)
            for column in signals.values():  # NaN where a report failed
                column.extend([np.nan] * (len(rows["t"]) + 1 - len(column)))
            u = dq / dt if faults.aborted is None else _brake(u, braking)
            sim.command(u)
            rows["t"].append(t)
            rows["q"].append(q)
            rows["u"].append(u)
            rows["time"].append(elapsed)
            sim.run_until(t + dt)
            report_time(t + dt, scenario.spec.duration)
            if faults.aborted is not None:
                break
    finally:
        sim.close()
    m = len(rows["t"])
    return Trace(
        method="velocity",
        t=np.array(rows["t"], dtype=float),
        q=np.array(rows["q"], dtype=float).reshape(m, robot.nq),
        ee_position=np.array(rows["ee_p"], dtype=float).reshape(m, 3),
        ee_rotation=np.array(rows["ee_R"], dtype=float).reshape(m, 3, 3),
        goal_position=np.full((m, 3), np.nan),
        goal_rotation=np.full((m, 3, 3), np.nan),
        q_names=robot.coordinate_names("q"),
        v_names=robot.coordinate_names("v"),
        events=events,
        compute_s=np.array(rows["time"], dtype=float),
        u=np.array(rows["u"], dtype=float).reshape(m, robot.nv),
        inputs={n: np.array(v) for n, v in values.items()},
        signals={k: np.array(v) for k, v in signals.items()},
        transient_s=settings.transient_s,
        aborted=faults.aborted,
    )


def _brake(u: FloatArray, braking: FloatArray) -> FloatArray:
    """The command after ``u`` that slows every joint by at most ``braking``."""
    return np.asarray(u - np.clip(u, -braking, braking))
