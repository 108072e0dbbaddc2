# SPDX-License-Identifier: Apache-2.0
"""One place that assembles a simulated run: :func:`build_run`.

A run is made of parts: the robot behind the seam (:mod:`cbp.driver`; a
simulated one, :class:`~cbp.driver.simulated.SimulatedRobot`), the collision world, the
goal input (a scenario's stream or an operator's live goal), the cameras and
their map, the declared objects that appear or move, the run's log and its
fault counter, and the clock planning budgets are counted on. The scenario is
data; :func:`build_run` makes the parts from it and returns them as one frozen
:class:`RunParts`, and a loop (the trajectory executors' period loop, the
torque loop of JT) drives a planner with them. A different goal source or
clock is an argument, not a subclass.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cbp.collision.world import CollisionWorld
from cbp.driver.process import ProcessRobot, RobotSetup
from cbp.driver.simulated import SimulatedRobot
from cbp.goals import GoalSource
from cbp.methods import method_info
from cbp.methods.settings import ClockKind
from cbp.robot import FloatArray, RobotModel
from cbp.run.cameras import Cameras
from cbp.run.declared import DeclaredObjects
from cbp.run.events import RunLog
from cbp.run.faults import STOPPED_EARLY, Faults
from cbp.run.goal_input import GoalBounds, GoalInput
from cbp.run.recording import make_trace
from cbp.run.robot_link import RobotLink
from cbp.scenario.runtime import Scenario
from cbp.sim.scene import simulate
from cbp.sim.simulation import Simulation
from cbp.trace import Trace

__all__ = ["OBJECT_UPDATE", "RunParts", "build_run"]

#: Declared objects that appear or move reach the collision world this often
#: (simulated time) [s]: as a tracker of known objects would report them.
OBJECT_UPDATE = 0.01


@dataclass(frozen=True)
class RunParts:
    """The parts of one simulated run (:func:`build_run` makes them).

    Attributes:
        scenario: the loaded scenario.
        arm: the robot, as the controller reaches it (:mod:`cbp.driver`).
        world: the collision world (None when neither an entry, the method
            nor the cameras need one).
        goal: the operator's goal as the run takes it.
        cameras: the depth cameras and their map (None without cameras).
        declared: the declared objects that appear or move, kept up to date
            in the world (None with cameras: the map discovers them).
        log: events, command periods and counters.
        faults: failures in a row, and whether the run was aborted.
        clock: how planning budgets are counted (``wall`` or ``virtual``).
    """

    scenario: Scenario
    arm: RobotLink
    world: CollisionWorld | None
    goal: GoalInput
    cameras: Cameras | None
    declared: DeclaredObjects | None
    log: RunLog
    faults: Faults
    clock: ClockKind

    @property
    def method(self) -> str:
        """The method that runs."""
        return self.log.method

    @property
    def robot(self) -> RobotModel:
        """The robot."""
        return self.scenario.robot

    @property
    def duration(self) -> float:
        """Length of the run [s]."""
        return self.scenario.spec.duration

    @property
    def ee_frame(self) -> str:
        """The frame that tracks the goal (the goal task's, else the robot's)."""
        return self.scenario.ee_frame

    def event(self, t: float, message: str) -> None:
        """Record (and log) something that went wrong and was handled."""
        self.log.event(t, message)

    def unseen(self, points: FloatArray) -> np.ndarray:
        """Which points (n, 3) lie in unseen space that counts as an obstacle.

        All False without cameras or with ``perception.unknown: free``.
        """
        if self.cameras is None:
            return np.zeros(len(np.asarray(points).reshape(-1, 3)), dtype=bool)
        return self.cameras.unseen(points)

    def mapped_since(self, camera: str, t: float) -> int:
        """How many frames of ``camera`` captured at or after ``t`` the map holds.

        0 without cameras.
        """
        return 0 if self.cameras is None else self.cameras.mapped_since(camera, t)

    def seen(self) -> float | None:
        """The capture time of the newest frame in the map [s] (None: no cameras)."""
        return None if self.cameras is None else self.cameras.mapper.stamp

    def hold_reason(self, t: float) -> str | None:
        """Why the robot must hold at ``t`` (a camera without valid frames), or None."""
        return None if self.cameras is None else self.cameras.hold_reason(t)

    def advance(self, t: float, look_ahead: float = 0.0, reaction: float = 0.0) -> None:
        """Simulate (and perceive) until ``t``.

        Args:
            t: simulated time to reach [s].
            look_ahead: how long the plan being made runs on the robot [s]:
                moving obstacles, declared (``collision.predict_motion``) or
                mapped, are measured that far ahead.
            reaction: how long the robot takes to begin answering what it
                meets [s] (a trajectory executor: two command periods), for
                the separation declared moving objects need.
        """
        self.log.progress(t)
        declared = self.declared
        arm = self.arm
        if declared is not None and declared.dynamic:
            # Declared objects that appear or move: the world is brought up to
            # date every OBJECT_UPDATE of simulated time.
            while arm.t + OBJECT_UPDATE < t:
                arm.run_until(arm.t + OBJECT_UPDATE)
                self._update_declared(arm.t, look_ahead, reaction)
            arm.run_until(t)
            self._update_declared(arm.t, look_ahead, reaction)
        else:
            arm.run_until(t)
            if self.cameras is not None:
                self.cameras.take(arm.frames(), t, arm.q, look_ahead)

    def finish(self) -> Trace:
        """Stop the map and the simulator; return the trace."""
        aborted = self.faults.aborted
        if aborted is not None and aborted.startswith(STOPPED_EARLY):
            self.event(self.arm.t, f"run {aborted}: the outputs hold it up to here")
        if self.cameras is not None:
            self.cameras.close()
        recording = self.arm.recording()
        self.arm.close()
        latencies = self.arm.latencies()
        if latencies:
            # From a frame's capture to the command planned on it reaching
            # the robot.
            ms = 1e3 * np.asarray(latencies)
            self.log.counters["capture_to_command_median_ms"] = float(np.median(ms))
            self.log.counters["capture_to_command_p95_ms"] = float(
                np.percentile(ms, 95)
            )
        return make_trace(
            self.scenario,
            recording,
            self.goal.changes,
            self.log,
            aborted,
            self.ee_frame,
        )

    def close(self) -> None:
        """Stop the map and the simulator without making a trace."""
        if self.cameras is not None:
            self.cameras.close()
        self.arm.close()

    def _update_declared(self, t: float, look_ahead: float, reaction: float) -> None:
        assert self.declared is not None
        for name in self.declared.update(t, look_ahead):
            self.log.event(t, f"object '{name}' appeared")
        self.declared.watch(t, self.arm.q, reaction)


def build_run(
    scenario: Scenario,
    *,
    method: str,
    clock: ClockKind = "wall",
    gui: bool = False,
    goal: GoalSource | None = None,
    needs_world: bool = False,
    lockstep: bool = False,
) -> RunParts:
    """Assemble the parts of a simulated run of ``scenario`` by ``method``.

    The run binds its own plugins and world (:meth:`Scenario.bound`): the
    same scenario builds any number of runs, and :attr:`RunParts.scenario` is
    this run's binding of it.

    Args:
        scenario: the loaded scenario.
        method: the method that runs (:data:`cbp.methods.METHODS`).
        clock: ``virtual`` integrates each depth frame into the map as it is
            captured (what a planner sees then depends on simulated time only),
            ``wall`` in the map's worker (never blocking the loop).
        gui: show PyBullet's window.
        goal: the goal source, instead of the scenario's stream (an
            operator's live goal, held to the world's bounds and the arm's
            reach: :class:`~cbp.run.goal_input.GoalBounds`).
        needs_world: build the collision world even when neither an entry nor
            the method needs one (a session that may switch methods).
        lockstep: step the simulated robot in the loop even on the wall clock
            with ``simulation.own_process`` (a live session's wait steps it).

    Raises:
        ConfigError: an unknown method, or one that builds no map asked to run
            with the depth cameras.
    """
    row = method_info(method)
    scenario = scenario.bound()  # this run's own plugins and world
    spec = scenario.spec
    row.refuse_source(spec.perception.source, f"{scenario.path}: perception.source")
    use_cameras = spec.perception.source == "depth_camera"
    log = RunLog(method, spec.duration)
    arm = _robot(scenario, gui, gui or lockstep, use_cameras, clock, log)
    try:
        world = (
            scenario.world or scenario.new_world()
            if needs_world
            or row.checks_collisions
            or scenario.needs_collision_world
            or use_cameras
            else None
        )
        cameras = (
            Cameras(
                arm,
                spec.perception,
                world,
                clock,
                log,
                spec.collision.predict_motion,
            )
            if use_cameras and world is not None
            else None
        )
    except BaseException:
        arm.close()
        raise
    declared = (
        DeclaredObjects(scenario, world, log)
        if world is not None and cameras is None
        else None
    )
    return RunParts(
        scenario=scenario,
        arm=arm,
        world=world,
        goal=GoalInput(
            scenario.goal_stream() if goal is None else goal,
            scenario.goal_task(),
            log,
            world,
            perceived=cameras is not None,
            bounds=None if goal is None else GoalBounds.of(scenario),
            reach=scenario.reach(),
        ),
        cameras=cameras,
        declared=declared,
        log=log,
        faults=Faults(log.event),
        clock=clock,
    )


def _robot(
    scenario: Scenario,
    gui: bool,
    stepped: bool,
    cameras: bool,
    clock: ClockKind,
    log: RunLog,
) -> RobotLink:
    """The run's simulated robot behind the seam, its cameras with it.

    In lockstep with the loop, or in its own process on the wall clock with
    ``simulation.own_process`` (:mod:`cbp.driver.process`) unless it must be
    ``stepped`` (a window, a live session).
    """
    spec = scenario.spec
    specs = spec.perception.all_cameras if cameras else ()
    driver: SimulatedRobot | ProcessRobot
    if clock == "wall" and spec.simulation.own_process and not stepped:
        driver = ProcessRobot(
            RobotSetup(
                scenario.robot,
                spec.world.objects,
                scenario.q0,
                spec.simulation,
                scenario.path.parent,
                tuple(specs),
                # Where the robot writes what it did if this process dies.
                record=Path(tempfile.gettempdir()) / f"cbp-robot-{os.getpid()}.npz",
                simulator=spec.simulator,
            )
        )
    else:
        sim = simulate(Simulation, scenario, gui)
        try:
            driver = SimulatedRobot(sim, specs)
        except BaseException:
            sim.close()
            raise
    return RobotLink(driver, lambda fault: log.event(fault.stamp, fault.message))
