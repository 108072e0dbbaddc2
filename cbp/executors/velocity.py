# SPDX-License-Identifier: Apache-2.0
"""The velocity executor: one QP per control tick, velocities to the robot.

For mobile manipulators driven by velocity (the orbit paper's Problem 4.3): each
tick of ``method.velocity.dt`` the operator's inputs (functions of time, the
scenario's ``inputs:``) are handed to their entries, the engine solves the QP
from the measured configuration, and ``u = dq / dt`` (base v_x, v_y, yaw rate,
then the arm's joints) is sent to the simulator. Orbit object and pan object are
configurations (``scenarios/youbot_*.yaml``), not code here.

A bad input value is refused (the entry keeps its previous one); a QP that
cannot be solved stops the robot for that tick. Both are events, and the loop
goes on.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cbp.errors import PluginOutputError, SolveError
from cbp.robot import FloatArray
from cbp.scenario import Scenario
from cbp.sim.mobile import MobileSimulation
from cbp.state import RobotState

__all__ = ["VelocityTrace", "orbit_metrics", "orbit_signals", "run_velocity"]

log = logging.getLogger(__name__)


@dataclass
class VelocityTrace:
    """What a velocity-executor run recorded, one row per tick.

    Attributes:
        t: tick times (N,) [s].
        q: measured configurations (N, nq).
        u: commanded velocities (N, nv).
        compute_s: wall time of each tick's QP (N,) [s].
        inputs: the inputs' values at each tick, by entry name (N, k).
        signals: the orbit's quantities over time (see :func:`orbit_signals`).
        events: (time, message) of refused inputs and failed solves.
    """

    t: FloatArray
    q: FloatArray
    u: FloatArray
    compute_s: FloatArray
    inputs: dict[str, FloatArray]
    signals: dict[str, FloatArray] = field(default_factory=dict)
    events: list[tuple[float, str]] = field(default_factory=list)


def run_velocity(scenario: Scenario, gui: bool = False) -> VelocityTrace:
    """Run ``scenario`` with the velocity executor; return the trace."""
    robot = scenario.robot
    dt = scenario.spec.method.velocity.dt
    engine = scenario.make_engine()
    inputs = scenario.inputs()
    names = {id(e.plugin): e.name for e in scenario.entries}
    steps = math.ceil(scenario.spec.duration / dt)
    rows: dict[str, list[Any]] = {"t": [], "q": [], "u": [], "time": []}
    values: dict[str, list[FloatArray]] = {names[id(p)]: [] for p, _ in inputs}
    events: list[tuple[float, str]] = []
    failing = 0
    sim = MobileSimulation(
        robot,
        scenario.spec.world.objects,
        scenario.q0,
        scenario.spec.simulation,
        scenario.path.parent,
        gui,
    )
    try:
        for k in range(steps):
            t = k * dt
            for plugin, functions in inputs:
                name = names[id(plugin)]
                value = np.array([f(t) for f in functions])
                try:
                    plugin.set_input(value)  # type: ignore[attr-defined]
                except (ValueError, ArithmeticError) as exc:
                    events.append((t, f"input to '{name}' refused: {exc}"))
                values[name].append(value)
            q = sim.q
            start = time.perf_counter()
            try:
                dq = engine.step(q, dt)
            except (SolveError, PluginOutputError) as exc:
                dq = np.zeros(robot.nv)
                failing += 1
                if failing == 1:  # one event per run of failed ticks
                    events.append((t, f"step not solved, robot stopped: {exc}"))
                    log.warning("t=%.3f s: %s", t, exc)
            else:
                if failing:
                    events.append((t, f"solved again after {failing} failed ticks"))
                failing = 0
            elapsed = time.perf_counter() - start
            u = dq / dt
            sim.command(u)
            rows["t"].append(t)
            rows["q"].append(q)
            rows["u"].append(u)
            rows["time"].append(elapsed)
            sim.run_until(t + dt)
    finally:
        sim.close()
    trace = VelocityTrace(
        t=np.array(rows["t"]),
        q=np.array(rows["q"]),
        u=np.array(rows["u"]),
        compute_s=np.array(rows["time"]),
        inputs={n: np.array(v) for n, v in values.items()},
        events=events,
    )
    trace.signals = orbit_signals(scenario, trace)
    return trace


def orbit_signals(scenario: Scenario, trace: VelocityTrace) -> dict[str, FloatArray]:
    """The orbit paper's plotted quantities, from the entries the scenario has.

    ``distance`` and ``distance_desired`` (orbit_distance), ``view_error_deg``
    (view_direction), ``roll_deg`` (no_roll), ``altitude`` and ``min_altitude``
    (min_altitude), ``obstacle_distance`` and ``min_obstacle_distance``
    (obstacle_distance).
    """
    state = RobotState(scenario.robot)
    by_type = {e.plugin.type_name: e for e in scenario.entries}
    n = trace.t.size
    out: dict[str, FloatArray] = {}
    series: dict[str, list[float]] = {}
    for i in range(n):
        state.update(trace.q[i])
        for type_name, entry in by_type.items():
            plugin: Any = entry.plugin
            if type_name == "orbit_distance":
                series.setdefault("distance", []).append(
                    float(plugin.compute_value(state)[0])
                )
            elif type_name == "view_direction":
                series.setdefault("view_error_deg", []).append(
                    math.degrees(plugin.angle(state))
                )
            elif type_name == "no_roll":
                series.setdefault("roll_deg", []).append(
                    math.degrees(plugin.roll(state))
                )
            elif type_name == "min_altitude":
                series.setdefault("altitude", []).append(
                    float(plugin.compute_value(state)[0])
                )
            elif type_name == "obstacle_distance":
                series.setdefault("obstacle_distance", []).append(
                    float(plugin.compute_value(state)[0])
                )
    out = {k: np.array(v) for k, v in series.items()}
    if "orbit_distance" in by_type:
        entry = by_type["orbit_distance"]
        recorded = trace.inputs.get(entry.name)
        out["distance_desired"] = (
            recorded[:, 0]
            if recorded is not None and recorded.size
            else np.full(n, entry.plugin.params.distance)
        )
    if "min_altitude" in by_type:
        params: Any = by_type["min_altitude"].plugin.params
        out["min_altitude"] = np.full(n, params.min_height)
    if "obstacle_distance" in by_type:
        params = by_type["obstacle_distance"].plugin.params
        out["min_obstacle_distance"] = np.full(n, params.min_distance)
    return out


def orbit_metrics(scenario: Scenario, trace: VelocityTrace) -> dict[str, float | None]:
    """Metrics of an orbit run; the first ``transient_s`` is left out of the errors."""
    transient = scenario.spec.method.velocity.transient_s
    s = trace.signals
    after = trace.t >= transient

    def worst(key: str, values: FloatArray | None = None) -> float | None:
        if key not in s and values is None:
            return None
        v = np.abs(values if values is not None else s[key])[after]
        return float(np.max(v)) if v.size else None

    def margin(key: str, bound: str) -> float | None:
        if key not in s:
            return None
        return float(np.min(s[key] - s[bound]))

    base_xy = trace.q[:, :2]
    return {
        "transient_s": transient,
        "distance_error_max_m": (
            worst("distance", s["distance"] - s["distance_desired"])
            if "distance" in s
            else None
        ),
        "view_error_max_deg": worst("view_error_deg"),
        "roll_max_deg": worst("roll_deg"),
        "altitude_margin_min_m": margin("altitude", "min_altitude"),
        "obstacle_margin_min_m": margin("obstacle_distance", "min_obstacle_distance"),
        "base_travel_m": float(
            np.sum(np.linalg.norm(np.diff(base_xy, axis=0), axis=1))
        ),
        "arm_travel_rad": float(np.sum(np.abs(np.diff(trace.q[:, 4:], axis=0)))),
        "compute_ms_per_tick_median": float(np.median(trace.compute_s) * 1e3),
        "events": float(len(trace.events)),
    }
