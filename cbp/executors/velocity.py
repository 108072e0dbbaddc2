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
``configs/orbit.yaml``; the loader adds it, and says so, to a scenario that
lists none) keeps the QP's answers within it. Hard inequality gains are held
to what the robot can brake (:func:`braking_gains`), and when not every row
can hold, the rows give way in order (:mod:`cbp.engine.recovery`): never the
robot's velocity and acceleration limits, then its position limits, then the
other constraints (obstacles), then the tasks and equalities (the orbit's).
A bad input value is refused (the entry keeps its previous one); a QP that
cannot be solved even so, or an answer the guard refuses, brakes the robot
for that tick within its acceleration limits. All are events, and the loop
goes on.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from cbp.errors import PluginOutputError, SolveError
from cbp.expressions import TimeFunction
from cbp.methods import METHODS
from cbp.methods.settings import VelocitySettings
from cbp.plugin import Constraint, ReportsSignals, TakesInput, UsesCollisionWorld
from cbp.qp import Entry
from cbp.robot import FloatArray
from cbp.run.declared import DeclaredObjects
from cbp.run.events import RunLog
from cbp.run.faults import Faults
from cbp.run.loop import run_ticks
from cbp.scenario.runtime import Scenario
from cbp.sim.mobile import MobileSimulation
from cbp.sim.scene import simulate
from cbp.state import RobotState
from cbp.trace import Trace

__all__ = ["VelocityLoop", "braking_gains", "run_velocity"]

log = logging.getLogger(__name__)


def run_velocity(scenario: Scenario, gui: bool = False) -> Trace:
    """Run ``scenario`` with the velocity executor; return the trace.

    Raises:
        ConfigError: the scenario asks for the depth cameras (no map here).
    """
    METHODS["velocity"].refuse_source(
        scenario.spec.perception.source, f"{scenario.path}: perception.source"
    )
    scenario = scenario.bound()  # this run's own plugins and world
    settings = scenario.spec.method.settings(VelocitySettings)
    sim = simulate(MobileSimulation, scenario, gui)
    loop = VelocityLoop(scenario, sim)
    run_log = RunLog("velocity", scenario.spec.duration)
    try:
        times = np.arange(math.ceil(scenario.spec.duration / settings.dt))
        # A tick counts its own faults (it brakes the robot and goes on);
        # the loop ends when they abort the run.
        run_ticks(
            _Inputs(loop, scenario.inputs()),
            times * settings.dt,
            run_log,
            Faults(run_log.event),
            "control step",
            stop=lambda: loop.faults.aborted is not None,
        )
    finally:
        sim.close()
    return loop.trace()


class _Inputs:
    """Each tick, the operator's inputs (functions of time), then the loop's QP."""

    def __init__(
        self,
        loop: VelocityLoop,
        inputs: list[tuple[TakesInput, list[TimeFunction]]],
    ) -> None:
        self.loop, self.inputs = loop, inputs

    def tick(self, t: float) -> None:
        for plugin, functions in self.inputs:
            self.loop.set_input(plugin, t, functools.partial(_evaluate, functions, t))
        self.loop.tick(t)

    def hold(self, t: float) -> None:
        """Nothing to do: a tick brakes the robot itself when its QP fails."""


class VelocityLoop:
    """One QP per tick from the measured configuration; velocities to the robot.

    :func:`run_velocity` drives it with the scenario's inputs (functions of
    time); a live session (:mod:`cbp.teleop`) with the operator's, and may
    switch between loops of several configurations of one robot (orbit and
    pan object) on one simulation: each tick starts from the last command,
    whichever loop gave it (:attr:`command`).

    Args:
        scenario: the configuration (its entries, inputs and settings).
        sim: the simulation it commands.
        command: the robot's last command (nv), shared with other loops on
            the same simulation; a new zero one (at rest) by default.
    """

    def __init__(
        self,
        scenario: Scenario,
        sim: MobileSimulation,
        command: FloatArray | None = None,
    ) -> None:
        """Build the engine and the recording."""
        robot = scenario.robot
        self.scenario, self.sim, self.robot = scenario, sim, robot
        self.settings = scenario.spec.method.settings(VelocitySettings)
        entries, lowered = braking_gains(scenario, self.settings.dt)
        # The same plugins, with the gains the robot can brake.
        braking = dataclasses.replace(scenario, entries=tuple(entries))
        self.engine = braking.make_engine()
        self.names = {id(e.plugin): e.name for e in scenario.entries}
        self.rows: dict[str, list[Any]] = {
            k: [] for k in ("t", "q", "u", "time", "ee_p", "ee_R")
        }
        self.frame_id = robot.frame_id(scenario.ee_frame)
        self.values: dict[str, list[FloatArray]] = {
            self.names[id(p)]: [] for p, _ in scenario.inputs()
        }
        self.events: list[tuple[float, str]] = [(0.0, m) for m in lowered]
        self.failing = 0
        self.reporters = [
            e.plugin for e in scenario.entries if isinstance(e.plugin, ReportsSignals)
        ]
        self.signals: dict[str, list[float]] = {}
        self.state = RobotState(robot)
        self.faults = Faults(lambda at, m: self.events.append((at, m)))
        for entry in scenario.entries:  # rows the loader added: said once
            added = getattr(entry.plugin, "added_because", None)
            if added is not None:
                self.events.append((0.0, added))
        if not any(e.plugin.robot_limit == "acceleration" for e in scenario.entries):
            self.events.append(
                (
                    0.0,
                    "no joint_acceleration constraint: answers that accelerate "
                    "past the limits are refused and the robot brakes",
                )
            )
        self.braking = robot.acceleration_limits * self.settings.dt
        #: Declared objects that appear or move, followed by the contact rows'
        #: world; measured a tick and the robot's stopping time ahead.
        world = scenario.world
        self.declared = (
            DeclaredObjects(scenario, world)
            if world is not None and scenario.spec.perception.source != "depth_camera"
            else None
        )
        self.look_ahead = self.settings.dt + robot.stopping_time()
        #: How the last solved step was eased (each change is an event).
        self._eased: str | None = None
        #: The last command (the robot starts at rest); updated in place.
        self.command = np.zeros(robot.nv) if command is None else command

    def set_input(
        self, plugin: TakesInput, t: float, values: Callable[[], list[float]]
    ) -> None:
        """Hand ``values()`` to ``plugin``; a value refused is an event.

        The entry then keeps its previous value; what was asked is recorded
        (NaN where it could not be computed).
        """
        name = self.names[id(plugin)]
        try:
            value = np.array(values(), dtype=float)
            plugin.set_input(value)
        except (ValueError, ArithmeticError, TypeError) as exc:
            value = np.full(plugin.input_size, np.nan)
            self.events.append((t, f"input to '{name}' refused: {exc}"))
        self.values[name].append(value)

    def tick(self, t: float) -> None:
        """Solve from the measured configuration, command, simulate one tick."""
        sim, dt, rows = self.sim, self.settings.dt, self.rows
        u = self.command
        q = sim.q
        start = time.perf_counter()
        if self.declared is not None:
            for name in self.declared.update(t, self.look_ahead):
                self.events.append((t, f"object '{name}' appeared"))
        try:
            result = self.engine.step(q, dt, u)
        except (SolveError, PluginOutputError) as exc:
            dq = _brake(u, self.braking) * dt
            self.failing += 1
            if self.failing == 1:  # one event per run of failed ticks
                self.events.append((t, f"step not solved, robot braking: {exc}"))
                log.warning("t=%.3f s: %s", t, exc)
        except Exception as exc:  # anything else: brake the robot, count it
            dq = _brake(u, self.braking) * dt
            self.faults.fault(t, "control step", exc)
        else:
            self.faults.ok()
            if self.failing:
                self.events.append(
                    (t, f"solved again after {self.failing} failed ticks")
                )
            self.failing = 0
            dq = result.dq
            eased = None if result.eased is None else result.eased.description
            if eased != self._eased and eased is not None:
                self.events.append((t, f"QP eased: {eased}"))
            self._eased = eased
        elapsed = time.perf_counter() - start
        # The end effector, and what the plugins report, at the tick's
        # measured configuration and with the inputs in effect.
        state = self.state
        state.update(q)
        placement = state.frame_placement(self.frame_id)
        rows["ee_p"].append(placement.translation.copy())
        rows["ee_R"].append(placement.rotation.copy())
        for reporter in self.reporters:
            try:
                reported = reporter.signals(state)
            except Exception as exc:  # a report is not worth stopping for
                self.faults.fault(t, "signal report", exc)
                continue
            for key, signal in reported.items():
                self.signals.setdefault(key, []).append(signal)
        for column in self.signals.values():  # NaN where a report failed
            column.extend([np.nan] * (len(rows["t"]) + 1 - len(column)))
        u_next = dq / dt if self.faults.aborted is None else _brake(u, self.braking)
        u[:] = u_next
        sim.command(u.copy())
        rows["t"].append(t)
        rows["q"].append(q)
        rows["u"].append(u.copy())
        rows["time"].append(elapsed)
        sim.run_until(t + dt)

    def trace(self) -> Trace:
        """The ticks so far as a trace."""
        robot, rows = self.robot, self.rows
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
            events=self.events,
            compute_s=np.array(rows["time"], dtype=float),
            u=np.array(rows["u"], dtype=float).reshape(m, robot.nv),
            inputs={n: np.array(v) for n, v in self.values.items()},
            signals={k: np.array(v) for k, v in self.signals.items()},
            transient_s=self.settings.transient_s,
            aborted=self.faults.aborted,
        )


def braking_gains(scenario: Scenario, dt: float) -> tuple[list[Entry], list[str]]:
    r"""The scenario's entries, each inequality's gain no more than the robot can brake.

    A hard inequality row with gain k lets the robot approach its bound at
    k / dt times its distance from it, so along that curve the robot must
    slow at k / dt times its speed. At a joint's top speed :math:`v_j` that is
    within its acceleration limit :math:`a_j` when
    :math:`k \le \Delta t\, a_j / v_j`; the gain of every hard inequality
    constraint that is not a limit of the robot's own is lowered to
    :math:`\Delta t \min_j a_j / v_j` (over the joints with both limits) if
    it is above it (for the youBot, 0.02 s x 1 m/s^2 / 0.8 m/s = 0.025).
    Above it, a base at speed reaches a point where an obstacle's row asks
    for more braking than it has, and the row gives way (still short of the
    bound). Equality rows (the orbit's distance and view) keep their gains.

    Returns:
        The entries (new ones where a gain was lowered), and one message per
        gain lowered.
    """
    robot = scenario.robot
    a, v = robot.acceleration_limits, robot.velocity_limits
    both = np.isfinite(a) & np.isfinite(v) & (v > 0)
    if not both.any():
        return list(scenario.entries), []
    j = int(np.flatnonzero(both)[np.argmin(a[both] / v[both])])
    cap = dt * float(a[j] / v[j])
    state = RobotState(robot, scenario.q0)
    entries, lowered = [], []
    for entry in scenario.entries:
        if entry.gain > cap and _brakes_toward(entry, state):
            lowered.append(
                f"gain of '{entry.name}' lowered from {entry.gain:g} to {cap:.4g}: "
                f"an inequality row approaches its bound at gain / dt times its "
                f"distance, and {robot.coordinate_names('v')[j]} slows from its "
                f"top speed ({v[j]:g}) at {a[j]:g} per s^2 (dt {dt:g} s)"
            )
            entry = dataclasses.replace(entry, gain=cap)
        entries.append(entry)
    return entries, lowered


def _brakes_toward(entry: Entry, state: RobotState) -> bool:
    """Whether ``entry`` is a hard inequality other than a limit of the robot's own.

    Its bounds at ``state`` differ (contact rows are inequalities whatever
    their bounds say before any contact is latched).
    """
    plugin = entry.plugin
    if not isinstance(plugin, Constraint) or entry.priority != "hard":
        return False
    if plugin.robot_limit is not None:
        return False
    if isinstance(plugin, UsesCollisionWorld):
        return True
    try:
        lower, upper = plugin.compute_bounds(state)
    except Exception:  # bounds that need a step's latch: an inequality
        return True
    return bool(np.any(np.asarray(lower) != np.asarray(upper)))


def _evaluate(functions: list[TimeFunction], t: float) -> list[float]:
    """The values of an input's functions at ``t``."""
    return [f(t) for f in functions]


def _brake(u: FloatArray, braking: FloatArray) -> FloatArray:
    """The command after ``u`` that slows every joint by at most ``braking``."""
    return np.asarray(u - np.clip(u, -braking, braking))
