# SPDX-License-Identifier: Apache-2.0
"""What every simulated executor shares: the simulator, the goal input, the map.

:class:`SimulatedRun` builds the PyBullet simulation from the scenario, samples
the operator's goal at the command rate (rejecting malformed samples, keeping the
previous goal, and saying so), runs the depth camera and the map thread when the
scenario asks for them, and turns the simulator's recording into a
:class:`~cbp.trace.Trace` with ground-truth clearances.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from cbp.collision.geometry import RobotGeometry
from cbp.collision.objects import PrimitiveEnvironment
from cbp.collision.world import CollisionSettings, CollisionWorld
from cbp.errors import InvalidTargetError
from cbp.executors.clock import ClockKind
from cbp.executors.declared import DeclaredObjects
from cbp.executors.faults import Faults
from cbp.goals import GoalSource
from cbp.perception.camera import DepthCamera, DepthFrame
from cbp.perception.kernels import UNKNOWN
from cbp.perception.map_process import ProcessMapUpdater
from cbp.perception.mapper import MapUpdater
from cbp.perception.motion import ApproachEstimator
from cbp.perception.occupancy import OccupancyGrid
from cbp.plugin import GoalReceiver
from cbp.progress import report_time
from cbp.robot import FloatArray
from cbp.scenario.runtime import Scenario
from cbp.sim.simulation import Simulation
from cbp.spatial import checked_se3
from cbp.state import RobotState
from cbp.trace import PeriodRecord, Trace

__all__ = ["SimulatedRun"]

log = logging.getLogger(__name__)

#: Ground-truth clearance is computed every this many seconds of the recording.
CLEARANCE_PERIOD = 0.02
#: Clearances beyond this are reported as this [m].
CLEARANCE_RANGE = 0.3
#: Declared objects that appear or move reach the collision world this often
#: (simulated time) [s]: as a tracker of known objects would report them.
OBJECT_UPDATE = 0.01


@dataclass
class _Goal:
    sample_t: float = -math.inf
    pose: pin.SE3 | None = None
    changes: list[tuple[float, pin.SE3]] = field(default_factory=list)


class SimulatedRun:
    """The simulation, goal input and perception of one run.

    Args:
        scenario: the loaded scenario.
        method: executor name (recorded in the trace).
        gui: show PyBullet's window.
        needs_world: build the collision world even if no entry uses it.
        clock: ``virtual`` integrates depth frames into the map in the control
            loop (the map a planner sees then depends on simulated time only),
            ``wall`` in the map thread (never blocking the loop).

    Attributes:
        sim: the simulation.
        world: the scenario's collision world (None if no entry or executor needs
            one and there is no depth camera).
        events: (time, message) of everything that went wrong and was handled.
        periods: command periods, filled in by trajectory executors.
        counters: numbers the executor counts (the trace's ``counters``).
        look_ahead: how long the plan being made runs on the robot [s]; moving
            declared objects are measured that far ahead
            (``collision.predict_motion``). Set by the trajectory executors.
    """

    def __init__(
        self,
        scenario: Scenario,
        method: str,
        gui: bool = False,
        needs_world: bool = False,
        clock: ClockKind = "wall",
    ) -> None:
        """Build the simulation; start the map if the scenario has a camera."""
        spec = scenario.spec
        self.scenario = scenario
        self.method = method
        self.robot = scenario.robot
        self.sim = Simulation(
            scenario.robot,
            spec.world.objects,
            scenario.q0,
            spec.simulation,
            scenario.path.parent,
            gui,
        )
        self.stream: GoalSource | None = scenario.goal_stream()
        self.goal_task: GoalReceiver | None = scenario.goal_task()
        self.events: list[tuple[float, str]] = []
        self.faults = Faults(self.event)
        self.periods: list[PeriodRecord] = []
        #: Numbers the executor counts over the run (into the trace's counters).
        self.counters: dict[str, float] = {}
        self._goal = _Goal()
        self._goal_failing = False
        self._goal_space_checked: tuple[object, FloatArray] = (None, np.zeros(0))
        self._goal_blocked = False
        use_camera = spec.perception.source == "depth_camera"
        self._look_ahead = 0.0
        self.world: CollisionWorld | None = None
        if needs_world or scenario.needs_collision_world or use_camera:
            self.world = scenario.collision_world()
        #: Declared objects that appear or move: the declared world follows them
        #: (with cameras, the map does).
        self._declared = (
            DeclaredObjects(scenario, self.world)
            if self.world is not None and not use_camera
            else None
        )
        self.mapper: MapUpdater | ProcessMapUpdater | None = None
        self.cameras: list[DepthCamera] = []
        self._next_frame: list[float] = []
        self._camera_state = RobotState(self.robot)
        #: Per camera: time of its last valid frame, and whether it is failing.
        self._last_valid: list[float] = []
        self._camera_failing: list[bool] = []
        self._stale: str | None = None
        if use_camera:
            assert self.world is not None
            self.world.set_environment(PrimitiveEnvironment([]))
            self.cameras = [
                DepthCamera(self.sim.client, camera, self.robot)
                for camera in spec.perception.all_cameras
            ]
            self._last_valid = [0.0] * len(self.cameras)
            self._camera_failing = [False] * len(self.cameras)
            grid = OccupancyGrid(spec.perception, self.world.geometry)
            # The robot looks once before it moves; later frames go to the thread.
            first = MapUpdater(grid, self.world, synchronous=True)
            for i in range(len(self.cameras)):
                frame = self._checked_frame(i, 0.0)
                if frame is not None:
                    first.submit(frame, self.sim.q.copy())
            perception = spec.perception
            estimator = (
                ApproachEstimator(self.world, perception.motion_window)
                if perception.motion_window > 0 and spec.collision.predict_motion
                else None
            )
            # Issue 39 (map off the control core): the map in its own process
            # in wall-clock runs unless perception.map_process is off.
            updater = (
                ProcessMapUpdater
                if perception.map_process and clock != "virtual"
                else MapUpdater
            )
            self.mapper = updater(
                grid, self.world, synchronous=clock == "virtual", estimator=estimator
            )
            self._next_frame = [1.0 / c.spec.rate_hz for c in self.cameras]

    # ------------------------------------------------------------------ goal input

    @property
    def look_ahead(self) -> float:
        """How long the plan being made runs on the robot [s] (see the class)."""
        return self._look_ahead

    @look_ahead.setter
    def look_ahead(self, seconds: float) -> None:
        """Set it; the map measures approaching obstacles that far ahead too."""
        self._look_ahead = seconds
        if self.mapper is not None:
            self.mapper.look_ahead = seconds

    @property
    def duration(self) -> float:
        """Length of the run [s]."""
        return self.scenario.spec.duration

    def goal(self, t: float) -> pin.SE3 | None:
        """The operator's goal at time ``t``: the latest valid sample of the stream.

        Samples are taken at the command rate; a malformed one (NaN, not a
        rotation) is rejected with an event and the previous goal stays.
        """
        stream = self.stream
        if stream is None:
            return None
        sample_t = math.floor(t * stream.rate_hz + 1e-9) / stream.rate_hz
        goal = self._goal
        if sample_t > goal.sample_t:
            goal.sample_t = sample_t
            try:
                position, rotation = stream.sample(sample_t)
            except Exception as exc:  # a goal source that fails: keep the goal
                if not self._goal_failing:
                    self.event(
                        t,
                        f"goal input failed ({type(exc).__name__}: {exc}); "
                        "previous goal kept",
                    )
                self._goal_failing = True
                return goal.pose
            if self._goal_failing:
                self.event(t, "goal input works again")
                self._goal_failing = False
            try:
                pose = checked_se3(position, rotation, "goal")
            except InvalidTargetError as exc:
                self.event(t, f"goal rejected, previous goal kept: {exc}")
            else:
                if goal.pose is None or not pose.isApprox(goal.pose, 1e-9):
                    goal.changes.append((sample_t, pose))
                goal.pose = pose
        return goal.pose

    def goal_changed(self) -> bool:
        """Whether the goal source has a goal newer than the last one sampled.

        Only a live source (the teleoperation page's) can: a scenario's stream
        is sampled at its rate. A planner that works through a period may
        check it between steps and take the newer goal (:meth:`resend_goal`).
        """
        return False

    def resend_goal(self) -> pin.SE3 | None:
        """Sample the goal source again now and send the goal on."""
        self._goal.sample_t = -math.inf
        return self.send_goal(self.sim.t)

    def send_goal(self, t: float) -> pin.SE3 | None:
        """Sample the goal at ``t`` and hand it to the scenario's goal task."""
        pose = self.goal(t)
        if pose is not None and self.goal_task is not None:
            self.goal_task.set_target(pose.translation, pose.rotation)
        if pose is not None:
            self._check_goal_space(t, pose)
        return pose

    def _check_goal_space(self, t: float, pose: pin.SE3) -> None:
        """Say when the goal enters or leaves an obstacle (or unseen space)."""
        world = self.world
        if world is None:
            return
        environment = world.environment
        checked_environment, checked_position = self._goal_space_checked
        if environment is checked_environment and np.array_equal(
            pose.translation, checked_position
        ):
            return
        self._goal_space_checked = (environment, pose.translation.copy())
        blocked = bool(environment.inside(pose.translation[None])[0])
        if blocked == self._goal_blocked:
            return
        self._goal_blocked = blocked
        if not blocked:
            self.event(t, "goal is in open space again")
        elif self.mapper is not None:
            self.event(
                t,
                "goal lies in an obstacle or in space no camera has seen "
                "(perception.unknown: occupied counts it as an obstacle): the arm "
                "stops short of it",
            )
        else:
            self.event(t, "goal lies inside an obstacle: the arm stops short of it")

    @property
    def goal_changes(self) -> list[tuple[float, pin.SE3]]:
        """Each accepted goal that differs from the one before, and its time."""
        return self._goal.changes

    @property
    def stop_requested(self) -> bool:
        """Whether the run should end now: an operator's stop, never in a script.

        The trajectory loop then ends at the period's start.
        """
        return False

    def commanded(self, t_start: float) -> None:
        """Called when a new trajectory, starting at ``t_start``, is spliced in."""

    def event(self, t: float, message: str) -> None:
        """Record (and log) something that went wrong and was handled."""
        self.events.append((t, message))
        log.info("%s t=%.3f s: %s", self.method, t, message)

    # ------------------------------------------------------------------ perception

    def unseen(self, points: FloatArray) -> np.ndarray:
        """Which points (n, 3) lie in unseen space that counts as an obstacle.

        Space no camera has seen and the robot has not held; all False without
        cameras or with ``perception.unknown: free``.
        """
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if self.mapper is None or not self.scenario.spec.perception.unknown_blocks:
            return np.zeros(len(points), dtype=bool)
        return np.asarray(self.mapper.grid.state_at(points) == UNKNOWN)

    def perceive_until(self, t: float) -> None:
        """Capture the camera frames due before ``t`` and hand them to the map."""
        if self.mapper is None:
            return
        due = self._next_frame
        while True:
            i = min(range(len(due)), key=due.__getitem__)
            if due[i] > t:
                break
            camera = self.cameras[i]
            self.sim.run_until(due[i])
            frame = self._checked_frame(i, due[i])
            if frame is not None:
                self.mapper.submit(frame, self.sim.q.copy(), due[i])
            if self.mapper.error is not None:
                error, self.mapper.error = self.mapper.error, None
                self.event(self.sim.t, f"map update: {error}")
            due[i] += 1.0 / camera.spec.rate_hz

    def _checked_frame(self, i: int, t: float) -> DepthFrame | None:
        """Camera ``i``'s frame at ``t`` if it is valid; else None and an event.

        A frame is valid when at least ``perception.min_valid_fraction`` of its
        pixels hold a reading (:meth:`DepthFrame.problem`). The first bad frame
        of a run of them is an event, and so is the first good one after.
        """
        camera = self.cameras[i]
        try:
            frame = self._capture(camera)
            problem = frame.problem(self.scenario.spec.perception.min_valid_fraction)
        except Exception as exc:  # a camera that fails is a camera without frames
            frame, problem = None, f"capture failed ({type(exc).__name__}: {exc})"
        if problem is None:
            if self._camera_failing[i]:
                self.event(t, f"camera '{camera.name}' gives valid frames again")
                self._camera_failing[i] = False
            self._last_valid[i] = t
            return frame
        if not self._camera_failing[i]:
            self.event(t, f"camera '{camera.name}': frame dropped, {problem}")
            self._camera_failing[i] = True
        return None

    def hold_reason(self, t: float) -> str | None:
        """Why the robot must hold at ``t``, or None.

        A camera whose last valid frame is older than
        ``perception.camera_timeout`` holds the robot until it gives one again
        (the map would otherwise go stale where the robot is heading). Each
        change is an event.
        """
        timeout = self.scenario.spec.perception.camera_timeout
        stale = [
            camera.name
            for camera, last in zip(self.cameras, self._last_valid, strict=True)
            if t - last > timeout
        ]
        reason = (
            f"no valid frame from camera {', '.join(repr(n) for n in stale)} for "
            f"more than {timeout:g} s: robot stopped"
            if stale
            else None
        )
        if reason is None and self.mapper is not None:  # issue 39: map failed, lags
            reason = self.mapper.hold_reason(timeout)
        if reason != self._stale:
            self.event(t, reason or "every camera gives valid frames: robot resumes")
            self._stale = reason
        return reason

    def _capture(self, camera: DepthCamera) -> DepthFrame:
        """One frame of ``camera``; a mounted one from the robot as it is now."""
        if not camera.mounted:
            return camera.capture()
        self._camera_state.update(self.sim.q.copy())
        return camera.capture(self._camera_state)

    def advance(self, t: float) -> None:
        """Simulate (and perceive) until ``t``."""
        report_time(t, self.duration)
        declared = self._declared
        moving = declared is not None and bool(declared.dynamic)
        if moving:
            # Declared objects that appear or move: the world is brought up to
            # date every OBJECT_UPDATE of simulated time.
            while self.sim.t + OBJECT_UPDATE < t:
                self.perceive_until(self.sim.t + OBJECT_UPDATE)
                self.sim.run_until(self.sim.t + OBJECT_UPDATE)
                self.update_declared(self.sim.t)
        self.perceive_until(t)
        self.sim.run_until(t)
        if moving:
            self.update_declared(self.sim.t)

    def update_declared(self, t: float) -> None:
        """Give the world the declared objects as they are at ``t``."""
        if self._declared is None:
            return
        for name in self._declared.update(t, self.look_ahead):
            self.event(t, f"object '{name}' appeared")

    # ------------------------------------------------------------------ results

    def finish(self) -> Trace:
        """Stop the map and the simulator; return the trace."""
        if self.mapper is not None:
            self.mapper.close()
        rec = self.sim.recording()
        self.sim.close()
        robot = self.robot
        model, data = robot.model, robot.model.createData()
        frame = robot.frame_id(self.ee_frame)
        n = rec["t"].size
        ee_p = np.empty((n, 3))
        ee_R = np.empty((n, 3, 3))
        for i in range(n):
            pin.framesForwardKinematics(model, data, rec["q"][i])
            M = data.oMf[frame]
            ee_p[i] = M.translation
            ee_R[i] = M.rotation
        goal_p = np.full((n, 3), np.nan)
        goal_R = np.full((n, 3, 3), np.nan)
        changes = self._goal.changes
        times = np.array([c[0] for c in changes])
        for i, t in enumerate(rec["t"]):
            k = int(np.searchsorted(times, t + 1e-9, side="right")) - 1
            if k >= 0:
                goal_p[i] = changes[k][1].translation
                goal_R[i] = changes[k][1].rotation
        change_time = float(times[1]) if times.size > 1 else None
        return Trace(
            method=self.method,
            t=rec["t"],
            q=rec["q"],
            q_cmd=rec["q_cmd"],
            ee_position=ee_p,
            ee_rotation=ee_R,
            goal_position=goal_p,
            goal_rotation=goal_R,
            q_names=robot.coordinate_names("q"),
            v_names=robot.coordinate_names("v"),
            contact_force=rec["contact_force"],
            wrist_force=rec["wrist_force"],
            penetration=rec["penetration"],
            clearance=self._clearance(rec["t"], rec["q"]),
            goal_change_time=change_time,
            periods=self.periods,
            events=self.events,
            aborted=self.faults.aborted,
            counters=dict(self.counters),
        )

    @property
    def ee_frame(self) -> str:
        """The frame that tracks the goal (the goal task's, else the robot's)."""
        return self.scenario.ee_frame

    def _clearance(self, t: FloatArray, q: FloatArray) -> FloatArray:
        """Unpadded links to declared objects, every CLEARANCE_PERIOD [m].

        Against the objects as they were at each sample's time.
        """
        out = np.full(t.size, np.nan)
        declared = self.scenario.spec.world.objects
        if not declared:
            out[:] = np.inf
            return out
        geometry = RobotGeometry(
            self.robot, padding=0.0, attachments=self.scenario.attachments()
        )
        settings = CollisionSettings(
            activation_distance=CLEARANCE_RANGE, self_collision=False, padding=0.0
        )
        world = CollisionWorld(
            geometry,
            PrimitiveEnvironment(self.scenario.environment_objects(0.0)),
            settings,
        )
        objects = DeclaredObjects(self.scenario, world)  # where they are, no look-ahead
        sample = float(np.median(np.diff(t))) if t.size > 1 else CLEARANCE_PERIOD
        stride = max(1, round(CLEARANCE_PERIOD / max(sample, 1e-6)))
        for i in range(0, t.size, stride):
            objects.update(float(t[i]))
            contacts = world.check(q[i]).contacts
            out[i] = (
                min(float(np.min(contacts.distance)), CLEARANCE_RANGE)
                if len(contacts)
                else CLEARANCE_RANGE
            )
        return out
