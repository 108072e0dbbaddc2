# SPDX-License-Identifier: Apache-2.0
"""A simulation behind the seam: a :class:`~cbp.driver.RobotDriver` of a simulated arm.

:class:`SimulatedRobot` is what a hardware driver is for a real arm: it
follows the commands it is sent (held to the joint limits first:
:func:`~cbp.driver.refusal`), brakes on its own when they go stale
(:class:`~cbp.driver.Watchdog`), and its cameras capture frames at their own
rates on the robot's clock. It is stepped by whoever owns it: the controller
itself on the virtual clock (:meth:`SimulatedRobot.advance`: lockstep, so runs
repeat exactly), or its own process in real time (:mod:`cbp.driver.process`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cbp.driver import (
    CameraFrame,
    Command,
    Fault,
    FaultKind,
    JointLimits,
    JointState,
    Watchdog,
    refusal,
)
from cbp.perception.spec import CameraSpec
from cbp.robot import FloatArray
from cbp.sim.camera import SimulatedCamera
from cbp.sim.cameras import depth_cameras
from cbp.sim.simulation import Simulation, TorqueController
from cbp.sim.trajectory import JointTrajectory, braking_now
from cbp.state import RobotState

__all__ = ["CameraRig", "SimulatedRobot"]


class CameraRig:
    """A robot's simulated cameras, each capturing at its rate on the robot's clock.

    Args:
        sim: the simulation the cameras render.
        specs: the cameras (``perception.cameras`` and the robot's own).
    """

    def __init__(self, sim: Simulation, specs: Sequence[CameraSpec]) -> None:
        """Build the cameras; the first frame of each falls due at once."""
        self._sim = sim
        # The simulation's engine's cameras (one ray caster for all, or one
        # OpenGL renderer per image size on MuJoCo).
        self.cameras = depth_cameras(sim, specs, sim.robot) if specs else []
        #: When each camera captures next [s].
        self.due = [sim.t for _ in self.cameras]
        self._state = RobotState(sim.robot)

    def next_due(self) -> float:
        """When the next frame falls due [s] (inf without cameras)."""
        return min(self.due, default=np.inf)

    def capture_due(self) -> list[CameraFrame]:
        """The frames due by the simulation's time, captured now, in camera order."""
        sim = self._sim
        frames = []
        for i, camera in enumerate(self.cameras):
            if self.due[i] > sim.t + 0.5 * sim.dt:
                continue
            frames.append(self._capture(camera, self.due[i]))
            self.due[i] += 1.0 / camera.spec.rate_hz
        return frames

    def close(self) -> None:
        """Release what the cameras render with (MuJoCo's OpenGL contexts)."""
        for camera in self.cameras:
            camera.close()

    def _capture(self, camera: SimulatedCamera, stamp: float) -> CameraFrame:
        q = self._sim.q.copy()
        try:
            if camera.mounted:
                self._state.update(q)
                frame = camera.capture(self._state)
            else:
                frame = camera.capture()
        except Exception as exc:  # a camera that fails gives no frame, and says why
            return CameraFrame(
                camera.name, stamp, q, None, f"{type(exc).__name__}: {exc}"
            )
        return CameraFrame(camera.name, stamp, q, frame)


class SimulatedRobot:
    """A simulated arm and its cameras behind the seam (:mod:`cbp.driver`).

    Args:
        sim: the simulation (its robot at its start).
        cameras: the cameras that capture on the robot's clock.
        timeout: the watchdog's limit [s] (:data:`~cbp.driver.COMMAND_TIMEOUT`
            for a robot that runs on its own); None: no watchdog (the
            controller steps the robot, so its commands cannot go stale).

    Attributes:
        sim: the simulation.
        latencies: per command that carried a frame's capture time, the
            time from that capture to the command's arrival [s].
    """

    def __init__(
        self,
        sim: Simulation,
        cameras: Sequence[CameraSpec] = (),
        timeout: float | None = None,
    ) -> None:
        """Wrap ``sim``; every camera captures its first frame.

        Nothing is commanded yet: the arm holds where it is.
        """
        self.sim = sim
        robot = sim.robot
        self._limits = JointLimits.of(robot)
        self._vmax = robot.velocity_limits
        self._amax = robot.acceleration_limits
        self._watchdog = Watchdog(timeout) if timeout is not None else None
        self.rig = CameraRig(sim, cameras)
        # The robot looks once before it moves.
        self._frames: list[CameraFrame] = self.rig.capture_due()
        self._faults: list[Fault] = []
        self._stopped = False
        self.latencies: list[float] = []

    # ------------------------------------------------------------ the seam

    @property
    def limits(self) -> JointLimits:
        """The limits commands are held to."""
        return self._limits

    def now(self) -> float:
        """The simulated time [s]."""
        return self.sim.t

    def state(self) -> JointState:
        """The joints now, and the contact force of the last physics step."""
        sim = self.sim
        return JointState(sim.t, sim.q.copy(), sim.v.copy(), float(sim.contact_force))

    def send(self, command: Command) -> None:
        """Follow ``command``; a refused one brakes the arm and is a fault."""
        if self._stopped:
            self.report("refused", "a command after stop: the robot takes no more")
            return
        why = refusal(command, self._limits)
        if why is not None:
            self.report("refused", f"command refused: {why}; braking")
            self.brake()
            return
        if self._watchdog is not None:
            self._watchdog.fed(command.stamp)
        if command.source is not None:
            self.latencies.append(self.sim.t - command.source)
        if command.trajectory is not None:
            self.sim.follow(command.trajectory)

    def frames(self) -> list[CameraFrame]:
        """The frames captured since the last call, oldest first."""
        frames, self._frames = self._frames, []
        return frames

    def faults(self) -> list[Fault]:
        """What the robot did on its own since the last call."""
        faults, self._faults = self._faults, []
        return faults

    def brake(self) -> None:
        """Come to rest along the trajectory followed, as fast as the limits allow."""
        sim = self.sim
        current = sim.trajectory
        braking = braking_now(current, sim.t, self._vmax, self._amax)
        if braking is not None:
            sim.follow(current.splice(braking))

    def stop(self) -> None:
        """Brake, and take no command after."""
        self.brake()
        self._stopped = True
        self.report("stopped", "stopped: braking to rest")

    # ------------------------------------------------------------ the robot's side

    def set_torque_controller(self, controller: TorqueController) -> None:
        """Drive the joints by torque every physics step (a 1 kHz torque interface)."""
        self.sim.set_torque_controller(controller)

    def advance(self, t: float) -> None:
        """Run the robot until its clock reads ``t`` [s].

        Physics step by step; at each, a stale command brakes the arm, and
        the cameras capture the frames that fall due.
        """
        sim, watchdog = self.sim, self._watchdog
        half = 0.5 * sim.dt
        while sim.t + half < t:
            if watchdog is not None and watchdog.trips(sim.t):
                self.report(
                    "stale_command",
                    f"no command for {sim.t - (watchdog.newest or 0.0):.3f} s "
                    f"(limit {watchdog.timeout:g} s): braking",
                )
                self.brake()
            sim.step()
            if self.rig.next_due() <= sim.t + half:
                self._frames.extend(self.rig.capture_due())

    def followed(self) -> JointTrajectory:
        """The trajectory the arm follows."""
        return self.sim.trajectory

    def recording(self) -> dict[str, FloatArray]:
        """The simulation's recording (:meth:`Simulation.recording`)."""
        return self.sim.recording()

    def close(self) -> None:
        """End the simulation (and release its cameras' renderers)."""
        self.rig.close()
        self.sim.close()

    def report(self, kind: FaultKind, message: str) -> None:
        """Report a fault of ``kind`` now (:meth:`faults` hands it on)."""
        self._faults.append(Fault(self.sim.t, kind, message))
