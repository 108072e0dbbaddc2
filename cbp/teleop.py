# SPDX-License-Identifier: Apache-2.0
"""``cbp teleop SCENARIO``: an operator drives the robot from the browser.

A :class:`TeleopSession` runs the scenario's simulation in real time with a
trajectory executor (CAT, IK, MP or hybrid, switchable at the next command
period) whose goal is the operator's: a :class:`LiveGoal` that the page (or any
caller of :meth:`TeleopSession.set_goal`) moves. :class:`TeleopPage` serves the
page with viser: the robot, the declared objects and, with cameras, the map's
occupied cells; the goal as a 6-DOF gizmo; a panel with the method, pause,
stop, jog buttons and a live readout.

Everything a goal stream goes through still applies: a malformed goal is
rejected with an event and the previous one kept; a goal in an obstacle is
approached without contact. A page that disconnects leaves the goal where it
was. When the session stops, the arm brakes on a trajectory it can follow, and
the outputs of ``cbp run`` are written, with the operator's goal stream as
``operator_goal.csv``: ``cbp compare SCENARIO --goal operator_goal.csv``
replays the session to every method.
"""

from __future__ import annotations

import logging
import math
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from cbp.collision.contacts import ContactSet
from cbp.errors import CbpError, ConfigError, require_choice
from cbp.executors import EXECUTORS, PERIODIC
from cbp.executors.clock import Budget
from cbp.executors.settings import CatSettings
from cbp.executors.simulated import SimulatedRun
from cbp.executors.trajectory import Plan, Planner, run_trajectory_executor
from cbp.goals import write_recorded
from cbp.plugin import HoldsContacts
from cbp.robot import FloatArray
from cbp.scenario import Scenario, load_scenario
from cbp.sim.trajectory import JointTrajectory
from cbp.state import RobotState
from cbp.trace import Trace

__all__ = ["METHODS", "LiveGoal", "TeleopSession"]

log = logging.getLogger(__name__)

#: The methods a session can switch between: the trajectory executors.
METHODS = PERIODIC
#: A session lasts until it is stopped, at most this long (the scenario
#: schema's longest duration) [s].
LONGEST = 86400.0
#: The shortest command period of a session [s], unless the scenario's
#: ``--set method.cat.timing.min_period`` says otherwise. The period shrinks
#: toward it while planning leaves time to spare (an arm at its goal), so a new
#: goal waits less for the next period: measured on the boards, goal-to-command
#: latency median 20 ms and p95 27 ms, against 50 and 63 ms with the nominal
#: 33 ms period throughout (``benchmarks/RESULTS.md``). Every method of a
#: session runs on these timings (CAT's).
MIN_PERIOD = 0.015
#: The operator's goal stream file in a session's outputs.
GOAL_FILE = "operator_goal.csv"


class LiveGoal:
    """The operator's goal: set from any thread, sampled by the control loop.

    Nothing is checked here: the run checks every sample as it does a
    scenario's stream (a malformed goal is rejected with an event).

    Args:
        position: the starting goal position (3,) [m].
        rotation: the starting goal rotation (3, 3).
        rate_hz: the rate at which the control loop samples it [Hz].
    """

    def __init__(
        self, position: FloatArray, rotation: FloatArray, rate_hz: float = 30.0
    ) -> None:
        """Start at the given pose."""
        self._lock = threading.Lock()
        self._position = np.array(position, dtype=float)
        self._rotation = np.array(rotation, dtype=float)
        self._rate_hz = float(rate_hz)
        #: Number of goals set so far (the starting one is 0).
        self.count = 0
        self._arrival: dict[int, float] = {0: time.perf_counter()}
        self._sampled = 0

    @property
    def rate_hz(self) -> float:
        """Rate at which the control loop samples the goal [Hz]."""
        return self._rate_hz

    def set(self, position: FloatArray, rotation: FloatArray) -> int:
        """Make (position, rotation) the goal; return its number."""
        with self._lock:
            self._position = np.array(position, dtype=float).reshape(3)
            self._rotation = np.array(rotation, dtype=float).reshape(3, 3)
            self.count += 1
            self._arrival[self.count] = time.perf_counter()
            return self.count

    def pose(self) -> tuple[FloatArray, FloatArray]:
        """The latest goal (copies)."""
        with self._lock:
            return self._position.copy(), self._rotation.copy()

    def sample(self, t: float) -> tuple[FloatArray, FloatArray]:
        """The latest goal; the control loop's sample at ``t`` [s]."""
        with self._lock:
            self._sampled = self.count
            return self._position.copy(), self._rotation.copy()

    def changed(self) -> bool:
        """Whether a goal was set after the last sample."""
        return self.count != self._sampled

    def take_sampled(self) -> tuple[int, float] | None:
        """The number and arrival time of the latest sampled goal, once each."""
        with self._lock:
            n = self._sampled
            arrival = self._arrival.pop(n, None)
            # Goals superseded before they were sampled have no latency.
            for old in [k for k in self._arrival if k < n]:
                del self._arrival[old]
        return None if arrival is None else (n, arrival)


class _SwitchingPlanner:
    """The selected method's planner; pausing brakes instead of planning."""

    def __init__(self, scenario: Scenario, run: SimulatedRun, method: str) -> None:
        self.scenario = scenario
        self.run = run
        self._planners: dict[str, Planner] = {}
        self.method = method
        self.wanted = method
        self.paused = False
        #: The contact sets last merged by :meth:`contacts`, and the result.
        self._merged: tuple[list[ContactSet], ContactSet] = ([], ContactSet.empty())
        self._planner(method)  # a method that cannot start fails before the run

    def _planner(self, method: str) -> Planner:
        planner = self._planners.get(method)
        if planner is not None:
            return planner
        planner = EXECUTORS[method].make_planner(self.scenario, self.run)
        self._planners[method] = planner
        return planner

    def plan(
        self, q: FloatArray, goal: pin.SE3 | None, budget: Budget, run: SimulatedRun
    ) -> Plan:
        """The selected planner's plan; a stop while paused."""
        if self.wanted != self.method:
            run.event(run.sim.t, f"method switched from {self.method} to {self.wanted}")
            self.method = self.wanted
        if self.paused:
            return Plan(None, 0, "paused", stop=True)
        return self._planner(self.method).plan(q, goal, budget, run)

    def contacts(self) -> ContactSet | None:
        """The obstacle contacts the method in control's contact rows hold.

        Those of every constraint that holds contacts (``contact_normals``, a
        user's own), with the environment: not the robot's own pairs. None when
        the method has no such rows or nothing is latched yet. The same set
        object until a row latches new contacts (the page redraws on change).
        """
        planner = self._planners.get(self.method)
        cat = getattr(planner, "cat", planner)  # hybrid's CAT, or CAT itself
        engine = getattr(cat, "engine", None)
        if engine is None:
            return None
        latched: list[ContactSet] = []
        for entry in engine.entries:
            if isinstance(entry.plugin, HoldsContacts):
                try:
                    latched.append(entry.plugin.contacts)
                except CbpError:  # nothing latched yet
                    continue
        if not latched:
            return None
        last, merged = self._merged
        if len(last) != len(latched) or any(
            a is not b for a, b in zip(last, latched, strict=True)
        ):
            merged = ContactSet.concatenate([c.environment_part() for c in latched])
            self._merged = (latched, merged)
        return merged

    def close(self) -> None:
        for planner in self._planners.values():
            close = getattr(planner, "close", None)
            if close is not None:
                close()


class _TeleopRun(SimulatedRun):
    """A simulated run paced to the wall clock, with the live goal and a stop."""

    def __init__(self, scenario: Scenario, method: str, goal: LiveGoal) -> None:
        super().__init__(scenario, method, needs_world=True, clock="wall")
        self.stream = goal
        self.live = goal
        self.stopping = threading.Event()
        self.latencies: list[float] = []
        self._wall0: float | None = None

    def advance(self, t: float) -> None:
        """Simulate until ``t``, then wait until the wall clock reaches it."""
        super().advance(t)
        now = time.perf_counter()
        if self._wall0 is None:
            self._wall0 = now - t
        wait = self._wall0 + t - now
        if wait > 0:
            time.sleep(wait)

    def goal_changed(self) -> bool:
        """Whether the operator sent a goal since the loop last sampled one."""
        return self.live.changed()

    @property
    def stop_requested(self) -> bool:
        """Stopping, and the robot at rest (its trajectory has ended)."""
        return self.stopping.is_set() and self.sim.trajectory.end_time <= self.sim.t

    def commanded(self, t_start: float) -> None:
        """Measure the latency of the goal this trajectory was planned for."""
        taken = self.live.take_sampled()
        if taken is None or self._wall0 is None:
            return
        _, arrival = taken
        starts = max(time.perf_counter(), self._wall0 + t_start)
        self.latencies.append(starts - arrival)


@dataclass
class Snapshot:
    """What the page shows of a session at one moment.

    Attributes:
        t: simulated time [s].
        q: joint positions.
        hand: the end effector's position (3,) [m].
        method: the method in control.
        paused: whether the arm is held.
        steps: planning steps of the last command period.
        misses: deadline misses so far.
        contact_force: contact force of the last physics step [N].
        events: the latest events, newest last.
        contacts: the contacts CAT's contact rows hold at its latest step
            (None for a method without them).
        trajectory: the trajectory the robot follows (a new object at each
            splice; its last point is where the arm is heading).
    """

    t: float
    q: FloatArray
    hand: FloatArray
    method: str
    paused: bool
    steps: int
    misses: int
    contact_force: float
    events: list[tuple[float, str]] = field(default_factory=list)
    contacts: ContactSet | None = None
    trajectory: JointTrajectory | None = None


class TeleopSession:
    """A scenario driven live: the simulation, the executor and the goal.

    Args:
        path: the scenario file.
        method: the method to start with (:data:`METHODS`).
        overrides: scenario values to replace (``--set``).

    Raises:
        ConfigError: an unknown method; ScenarioError: a bad scenario.
    """

    def __init__(
        self,
        path: str | Path,
        method: str = "cat",
        overrides: dict[str, str] | None = None,
    ) -> None:
        """Load the scenario and build the run; :meth:`start` starts it."""
        require_choice(method, METHODS, "method", "--method")
        values = {
            "duration": str(LONGEST),
            "method.cat.timing.min_period": str(MIN_PERIOD),
            **(overrides or {}),
        }
        self.path = Path(path)
        self.scenario = load_scenario(self.path, overrides=values)
        if self.scenario.goal_task() is None:
            raise ConfigError(
                f"{self.path}: the scenario has no goal_pose task to teleoperate"
            )
        robot = self.scenario.robot
        state = RobotState(robot, self.scenario.q0)
        hand = state.frame_placement(robot.frame_id(self.scenario.ee_frame))
        #: The hand's pose at the start: where the goal starts and resets to.
        self.home = (hand.translation.copy(), hand.rotation.copy())
        stream = self.scenario.goal_stream()
        self.goal = LiveGoal(*self.home, stream.rate_hz if stream else 30.0)
        self.run = _TeleopRun(self.scenario, method, self.goal)
        self.planner = _SwitchingPlanner(self.scenario, self.run, method)
        self.timing = self.scenario.spec.method.settings(CatSettings).timing
        self._state = RobotState(robot)
        self._frame = robot.frame_id(self.scenario.ee_frame)
        self._periods_counted = self._misses = 0
        self._thread: threading.Thread | None = None
        self.trace: Trace | None = None
        self.error: BaseException | None = None

    # ------------------------------------------------------------------ control

    def start(self) -> None:
        """Start the control loop in its own thread."""
        self._thread = threading.Thread(target=self._loop, name="teleop", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        try:
            self.trace = run_trajectory_executor(self.run, self.planner, self.timing)
        except BaseException as exc:  # kept for stop() to raise in the caller
            self.error = exc
        finally:
            self.planner.close()

    def set_goal(self, position: FloatArray, rotation: FloatArray) -> int:
        """Send a goal (the page's gizmo, a script); return its number."""
        return self.goal.set(position, rotation)

    def jog(self, axis: str, step: float, frame: str = "world") -> int:
        """Move the goal by ``step`` along or about an axis.

        From the latest goal sent, or, when that one was malformed (and
        rejected by the run), from the goal in force.

        Args:
            axis: ``x``, ``y``, ``z`` (translate by ``step`` [m]) or ``rx``,
                ``ry``, ``rz`` (rotate by ``step`` [rad]).
            step: the amount, signed.
            frame: ``world`` or ``hand`` (the goal's own axes).
        """
        require_choice(axis, ("x", "y", "z", "rx", "ry", "rz"), "axis", "jog")
        require_choice(frame, ("world", "hand"), "frame", "jog")
        position, rotation = self.goal.pose()
        if not (np.isfinite(position).all() and np.isfinite(rotation).all()):
            # The latest goal was malformed (and rejected): jog from the one
            # in force.
            accepted = self.run.goal_changes
            if accepted:
                position = accepted[-1][1].translation.copy()
                rotation = accepted[-1][1].rotation.copy()
            else:
                position, rotation = self.home[0].copy(), self.home[1].copy()
        unit = np.eye(3)["xyz".index(axis[-1])]
        if frame == "hand":
            unit = rotation @ unit
        if axis.startswith("r"):
            rotation = pin.exp3(unit * step) @ rotation
        else:
            position = position + unit * step
        return self.set_goal(position, rotation)

    def reset(self) -> int:
        """Put the goal back at the hand's starting pose."""
        return self.set_goal(*self.home)

    def pause(self, paused: bool = True) -> None:
        """Hold the arm (it brakes on its trajectory), or let it go on."""
        self.planner.paused = paused

    def switch(self, method: str) -> None:
        """Hand control to ``method`` at the next command period."""
        require_choice(method, METHODS, "method", "switch")
        self.planner.wanted = method

    def stop(self, timeout: float = 30.0) -> Trace:
        """Brake, end the run when the arm is at rest, and return its trace."""
        self.planner.paused = True
        self.run.stopping.set()
        if self._thread is not None:
            self._thread.join(timeout)
            if self._thread.is_alive():
                raise RuntimeError("the control loop did not stop in time")
        if self.error is not None:
            raise self.error
        if self.trace is None:
            raise RuntimeError("the session was not started")
        return self.trace

    def write(self, out: Path) -> Path:
        """Write the outputs of ``cbp run`` and the operator's goal stream."""
        from cbp.report import write_outputs

        if self.trace is None:
            raise RuntimeError("stop the session before writing it")
        changes = self.run.goal_changes
        if not changes:
            changes = [(0.0, pin.SE3(self.home[1], self.home[0]))]
        with tempfile.TemporaryDirectory() as folder:
            goal_file = Path(folder) / GOAL_FILE
            write_recorded(
                goal_file,
                [t for t, _ in changes],
                np.array([p.translation for _, p in changes]),
                np.array([p.rotation for _, p in changes]),
            )
            write_outputs(
                self.scenario,
                {self.trace.method: self.trace},
                out,
                extra_files={GOAL_FILE: goal_file},
            )
        return out / GOAL_FILE

    # ------------------------------------------------------------------ reading

    @property
    def running(self) -> bool:
        """Whether the control loop runs."""
        return self._thread is not None and self._thread.is_alive()

    def snapshot(self) -> Snapshot:
        """What the page shows now (read from the control thread's state)."""
        run = self.run
        q = np.array(run.sim.q, dtype=float)
        self._state.update(q)
        periods = run.periods
        # Deadline misses counted once per period (a session may run for hours).
        for period in periods[self._periods_counted :]:
            self._misses += period.missed
        self._periods_counted = len(periods)
        return Snapshot(
            t=run.sim.t,
            q=q,
            hand=self._state.frame_position(self._frame).copy(),
            method=self.planner.method,
            paused=self.planner.paused,
            steps=periods[-1].steps if periods else 0,
            misses=self._misses,
            contact_force=float(run.sim.contact_force),
            events=list(run.events[-5:]),
            contacts=self.planner.contacts(),
            trajectory=run.sim.trajectory,
        )

    def latency_ms(self) -> list[float]:
        """Goal-to-command latencies measured so far [ms]."""
        return [1e3 * x for x in self.run.latencies]


def latency_summary(latencies_ms: list[float]) -> dict[str, Any]:
    """Median, 95th percentile and count of latencies [ms]."""
    if not latencies_ms:
        return {"n": 0, "median_ms": math.nan, "p95_ms": math.nan}
    values = np.array(latencies_ms)
    return {
        "n": int(values.size),
        "median_ms": float(np.median(values)),
        "p95_ms": float(np.percentile(values, 95)),
    }


class InputSession:
    """Velocity-executor configurations of one robot driven live by their inputs.

    Orbit object and pan object (the orbit paper) are configurations of the
    velocity executor; a session loads one or several (scenario files of one
    robot) on one simulation, and the operator switches between them within
    the run (:meth:`switch`, at the next tick; the new one starts from the
    last command). Each configuration's inputs (``camera_velocity``'s
    camera-frame velocities, ``orbit_distance``'s desired distance) start at
    their scenario's values at t = 0 and are set with :meth:`set_input`; a
    value an entry refuses is an event and the entry keeps its previous one.

    Args:
        paths: the scenario files (``method.name: velocity``, one robot).
        overrides: values to replace in every one of them (``--set``).

    Raises:
        ConfigError: a scenario of another executor or robot.
    """

    def __init__(
        self, paths: list[Path], overrides: dict[str, str] | None = None
    ) -> None:
        """Load every configuration and build their loops on one simulation."""
        from cbp.executors.velocity import VelocityLoop
        from cbp.sim.mobile import MobileSimulation

        values = {"duration": str(LONGEST), **(overrides or {})}
        self.scenarios = [load_scenario(p, overrides=values) for p in paths]
        first = self.scenarios[0]
        for path, scenario in zip(paths, self.scenarios, strict=True):
            if scenario.spec.method.name != "velocity":
                raise ConfigError(
                    f"{path}: a '{scenario.spec.method.name}' scenario; with several "
                    "files, or one of the velocity executor, every file must be a "
                    "velocity-executor configuration"
                )
            if scenario.robot.name != first.robot.name:
                raise ConfigError(
                    f"{path}: robot '{scenario.robot.name}', not "
                    f"'{first.robot.name}' as in {paths[0]}"
                )
            EXECUTORS["velocity"].check(scenario)
        self.sim = MobileSimulation(
            first.robot,
            first.spec.world.objects,
            first.q0,
            first.spec.simulation,
            first.path.parent,
            False,
        )
        command = np.zeros(first.robot.nv)
        self.loops = {
            s.spec.name: VelocityLoop(s, self.sim, command) for s in self.scenarios
        }
        #: Each configuration's inputs by entry name: the values in force.
        self.inputs: dict[str, dict[str, FloatArray]] = {}
        self._plugins: dict[str, dict[str, Any]] = {}
        for scenario in self.scenarios:
            names = {id(e.plugin): e.name for e in scenario.entries}
            self.inputs[scenario.spec.name] = {
                names[id(p)]: np.array([f(0.0) for f in fs])
                for p, fs in scenario.inputs()
            }
            self._plugins[scenario.spec.name] = {
                names[id(p)]: p for p, _ in scenario.inputs()
            }
        self.active = first.spec.name
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.events: list[tuple[float, str]] = []
        self.t = 0.0
        self.error: BaseException | None = None

    @property
    def robot(self) -> Any:
        """The robot model."""
        return self.scenarios[0].robot

    def set_input(
        self, entry: str, values: FloatArray, config: str | None = None
    ) -> None:
        """Set an input of the active (or the named) configuration."""
        config = config or self.active
        require_choice(config, self.inputs, "configuration", "set_input")
        require_choice(entry, self.inputs[config], "input", "set_input")
        with self._lock:
            self.inputs[config][entry] = np.array(values, dtype=float)

    def switch(self, config: str) -> None:
        """Hand control to another configuration at the next tick."""
        require_choice(config, self.loops, "configuration", "switch")
        with self._lock:
            if config != self.active:
                self.events.append((self.t, f"switched from {self.active} to {config}"))
                self.active = config

    def start(self) -> None:
        """Run the ticks in real time in a thread of their own."""
        self._thread = threading.Thread(target=self._run, name="teleop", daemon=True)
        self._thread.start()

    @property
    def running(self) -> bool:
        """Whether the ticks run."""
        return self._thread is not None and self._thread.is_alive()

    def _run(self) -> None:
        try:
            dt = self.loops[self.active].settings.dt
            wall0 = time.perf_counter()
            k = 0
            while not self._stop.is_set():
                t = k * dt
                with self._lock:
                    loop = self.loops[self.active]
                    values = dict(self.inputs[self.active])
                for name, value in values.items():
                    plugin = self._plugins[self.active][name]
                    loop.set_input(plugin, t, value.tolist)
                loop.tick(t)
                self.t = t + dt
                k += 1
                if loop.faults.aborted is not None:
                    break
                wait = wall0 + k * dt - time.perf_counter()
                if wait > 0:
                    time.sleep(wait)
        except BaseException as exc:  # kept for stop() to raise in the caller
            self.error = exc

    def snapshot(self) -> dict[str, Any]:
        """Time, configuration, measured q and the active loop's latest signals."""
        loop = self.loops[self.active]
        signals = {k: v[-1] for k, v in loop.signals.items() if v}
        events = sorted(
            self.events + [e for lp in self.loops.values() for e in lp.events]
        )
        return {
            "t": self.t,
            "active": self.active,
            "q": np.array(self.sim.q, dtype=float),
            "signals": signals,
            "events": events[-5:],
        }

    def stop(self, timeout: float = 10.0) -> dict[str, Trace]:
        """Stop the ticks (the robot brakes to rest); each configuration's trace."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
        if self.error is not None:
            raise self.error
        traces = {}
        for name, loop in self.loops.items():
            if loop.rows["t"]:
                trace = loop.trace()
                trace.events.extend(e for e in self.events if e not in trace.events)
                traces[name] = trace
        self.sim.close()
        return traces

    def write(self, traces: dict[str, Trace], out: Path) -> None:
        """Write each configuration's run as ``cbp run`` would, in one folder."""
        from cbp.report import write_outputs

        write_outputs(self.scenarios[0], traces, out)
