# SPDX-License-Identifier: Apache-2.0
"""The controller's side of the seam: what it commanded, what the robot measured.

:class:`RobotLink` is the only way a run reaches its robot
(:class:`~cbp.driver.RobotDriver`): the loop and the executors read the
measured joints (:attr:`RobotLink.q`), splice trajectories onto the one they
commanded (:attr:`RobotLink.trajectory`, :meth:`RobotLink.follow`) and let
time pass (:meth:`RobotLink.run_until`). A simulated robot the controller
steps itself (:class:`Lockstep`: the virtual clock, runs that repeat exactly)
is stepped there; a robot that runs on its own (its own process, or hardware)
is waited for, and kept commanded by a heartbeat while the loop shows signs of
life (:class:`Heartbeat`). Frames and faults the robot reports are handed on.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Protocol, runtime_checkable

from cbp.driver import HEARTBEAT, CameraFrame, Command, Fault, JointState, RobotDriver
from cbp.robot import FloatArray
from cbp.sim.trajectory import TRAJECTORY_HISTORY, JointTrajectory

__all__ = ["LIVENESS", "Heartbeat", "Lockstep", "Recorded", "RobotLink", "Started"]

#: A loop that gives no sign of life for this long is hung: the heartbeat
#: stops, and the robot's watchdog brakes the arm [s].
LIVENESS = 1.0

#: While waiting for a robot's clock, the link sleeps at most this long [s].
WAIT_STEP = 0.002


@runtime_checkable
class Lockstep(Protocol):
    """A robot the controller steps itself (a simulation on the virtual clock)."""

    def advance(self, t: float) -> None:
        """Run the robot until its clock reads ``t`` [s]."""
        ...


@runtime_checkable
class Started(Protocol):
    """A robot whose clock starts with the run (a simulation in its own process)."""

    def start(self) -> None:
        """Start the robot's clock."""
        ...


@runtime_checkable
class Recorded(Protocol):
    """A robot that records what it did (a simulation: joints, contact forces)."""

    def recording(self) -> dict[str, FloatArray]:
        """The recorded samples (:meth:`cbp.sim.simulation.Simulation.recording`)."""
        ...

    @property
    def latencies(self) -> list[float]:
        """Per command that carried a frame's capture time, capture to arrival [s]."""
        ...

    def close(self) -> None:
        """End the robot (its process, its simulation)."""
        ...


class Heartbeat:
    """Keeps a robot that runs on its own commanded while the loop lives.

    A thread sends a command without a trajectory every
    :data:`~cbp.driver.HEARTBEAT` while the loop's last sign of life
    (:meth:`alive`) is younger than :data:`LIVENESS`; a loop that hangs, or a
    process that is killed, lets the robot's watchdog brake the arm.
    """

    def __init__(self, driver: RobotDriver) -> None:
        """Start beating."""
        self._driver = driver
        self._lock = threading.Lock()
        self._last_sign = time.monotonic()
        self._done = threading.Event()
        self._thread = threading.Thread(
            target=self._beat, name="heartbeat", daemon=True
        )
        self._thread.start()

    def alive(self) -> None:
        """The loop is alive now."""
        self._last_sign = time.monotonic()

    def send(self, command: Command) -> None:
        """Send ``command`` (one sender at a time)."""
        with self._lock:
            self._driver.send(command)

    def close(self) -> None:
        """Stop beating."""
        self._done.set()
        self._thread.join(timeout=1.0)

    def _beat(self) -> None:
        while not self._done.wait(HEARTBEAT):
            if time.monotonic() - self._last_sign < LIVENESS:
                self.send(Command(self._driver.now()))


class RobotLink:
    """The run's robot as the controller sees it: measured state, commanded motion.

    Args:
        driver: the robot (:class:`~cbp.driver.RobotDriver`).
        on_fault: called with each fault the robot reports.

    Attributes:
        driver: the robot.
        trajectory: the trajectory last commanded (the recent past kept).
    """

    def __init__(
        self, driver: RobotDriver, on_fault: Callable[[Fault], None] | None = None
    ) -> None:
        """Read the robot's state; it holds where it is until commanded."""
        self.driver = driver
        self._state: JointState = driver.state()
        self.trajectory = JointTrajectory.hold(self._state.stamp, self._state.q)
        self._steps = driver if isinstance(driver, Lockstep) else None
        self._heart = None if self._steps is not None else Heartbeat(driver)
        self._on_fault = on_fault
        self._frames: list[CameraFrame] = []

    @property
    def lockstep(self) -> bool:
        """Whether the controller steps the robot (else it runs on its own)."""
        return self._steps is not None

    @property
    def t(self) -> float:
        """The robot's clock [s]."""
        return self.driver.now()

    @property
    def q(self) -> FloatArray:
        """The joint positions last measured."""
        return self._state.q

    @property
    def contact_force(self) -> float:
        """The contact force the robot last measured [N]."""
        return self._state.force

    def follow(self, trajectory: JointTrajectory, source: float | None = None) -> None:
        """Command ``trajectory`` from now on.

        Args:
            trajectory: the motion (on the robot's clock).
            source: the capture time of the newest frame the plan saw [s].
        """
        self.trajectory = trajectory.since(self.t - TRAJECTORY_HISTORY)
        command = Command(self.driver.now(), self.trajectory, source)
        if self._heart is None:
            self.driver.send(command)
        else:
            self._heart.alive()
            self._heart.send(command)

    def run_until(self, t: float) -> None:
        """Let the robot's clock reach ``t`` [s]; read its state, frames and faults.

        A robot in lockstep is stepped there; one that runs on its own is
        waited for.
        """
        if self._steps is not None:
            self._steps.advance(t)
        else:
            assert self._heart is not None
            self._heart.alive()
            if isinstance(self.driver, Started):
                self.driver.start()  # the run's time begins
            while (left := t - self.driver.now()) > 0:
                time.sleep(min(left, WAIT_STEP))
        self.refresh()

    def refresh(self) -> None:
        """Read the robot's newest state, frames and faults."""
        driver = self.driver
        self._state = driver.state()
        self._frames.extend(driver.frames())
        if self._on_fault is not None:
            for fault in driver.faults():
                self._on_fault(fault)

    def frames(self) -> list[CameraFrame]:
        """The frames received since the last call, oldest first."""
        frames, self._frames = self._frames, []
        return frames

    def recording(self) -> dict[str, FloatArray]:
        """What the robot recorded (a simulated robot)."""
        if not isinstance(self.driver, Recorded):
            raise TypeError(f"{type(self.driver).__name__} keeps no recording")
        return self.driver.recording()

    def latencies(self) -> list[float]:
        """Capture-to-command latencies the robot measured [s] (after the recording)."""
        return self.driver.latencies if isinstance(self.driver, Recorded) else []

    def close(self) -> None:
        """Stop the heartbeat; end a simulated robot."""
        if self._heart is not None:
            self._heart.close()
        if isinstance(self.driver, Recorded):
            self.driver.close()
