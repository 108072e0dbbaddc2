# SPDX-License-Identifier: Apache-2.0
"""A simulated robot in its own process, in real time: a robot that does not wait.

:class:`ProcessRobot` is a :class:`~cbp.driver.RobotDriver` whose robot
(:class:`~cbp.driver.simulated.SimulatedRobot`: physics, cameras, watchdog) runs in
a process of its own, as hardware runs beside its controller: once started,
its physics keeps the wall clock's pace whatever the controller does, each
camera captures at its own rate, and commands that go stale brake the arm
(:data:`~cbp.driver.COMMAND_TIMEOUT`). The controller reaches it only through
the seam: commands go down a pipe, and the robot's state (every
:data:`STATE_EVERY`), frames and faults come up it, each stamped on the
robot's clock: its simulated time, which keeps the wall clock's pace from
:meth:`ProcessRobot.start` on as long as the machine lets it (else it
says so, and runs slower).

A robot whose controller dies (killed, or hung so that its heartbeat stops)
brakes on its watchdog, holds at rest for :data:`ORPHAN_HOLD`, writes its
recording (when it was given a file) and ends.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import threading
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any

import numpy as np

from cbp.driver import (
    COMMAND_TIMEOUT,
    CameraFrame,
    Command,
    Fault,
    JointLimits,
    JointState,
)
from cbp.perception.spec import CameraSpec
from cbp.robot import FloatArray, RobotModel
from cbp.scenario.scene import ObjectSpec, SimulationSettings

__all__ = ["ORPHAN_HOLD", "STATE_EVERY", "ProcessRobot", "RobotSetup"]

#: The robot sends its state this often [s] (of its clock).
STATE_EVERY = 0.002

#: The physics runs in slices of at most this much robot time between reads
#: of the commands [s]: a robot behind the wall clock catches up in them.
SLICE = 0.002

#: A robot more than this behind the wall clock says so (a fault) [s].
LAG_LIMIT = 0.05

#: A robot whose controller is gone holds at rest this long, then ends [s].
ORPHAN_HOLD = 1.0

#: Joints slower than this are at rest [rad/s].
REST_SPEED = 1e-3

#: How long the robot's process may take to start [s].
START_TIMEOUT = 120.0


@dataclass(frozen=True)
class RobotSetup:
    """What the robot's process builds its simulation from (picklable).

    Attributes:
        robot: the robot model.
        objects: the scene's objects.
        q0: the start configuration.
        settings: the ``simulation:`` section.
        folder: where mesh files of objects are resolved from.
        cameras: the cameras that capture on the robot's clock.
        timeout: the watchdog's limit [s].
        record: where the robot writes its recording if its controller dies
            (None: nowhere).
        simulator: the physics engine (:data:`cbp.sim.physics.SIMULATORS`).
    """

    robot: RobotModel
    objects: list[ObjectSpec]
    q0: FloatArray
    settings: SimulationSettings
    folder: Path
    cameras: tuple[CameraSpec, ...] = ()
    timeout: float = COMMAND_TIMEOUT
    record: Path | None = None
    simulator: str = "pybullet"


class ProcessRobot:
    """A simulated robot running on its own in a child process (a :class:`RobotDriver`).

    Args:
        setup: what the robot is built from.

    Raises:
        RuntimeError: the process did not start (its reason).
    """

    def __init__(self, setup: RobotSetup) -> None:
        """Start the process; wait until its robot stands at its start."""
        context = _context()
        ours, theirs = context.Pipe(duplex=True)
        self._conn: Connection = ours
        self._process = context.Process(
            target=_child, args=(setup, theirs), name="cbp-robot", daemon=True
        )
        self._process.start()
        theirs.close()
        ready = wait([ours, self._process.sentinel], START_TIMEOUT)
        if ours not in ready:
            self._process.kill()
            raise RuntimeError(
                f"the robot's process did not start (exit code "
                f"{self._process.exitcode})"
            )
        message = ours.recv()
        if message[0] != "ready":
            self._process.join(5.0)
            raise RuntimeError(f"the robot's process did not start: {message[1]}")
        self._limits: JointLimits = message[1]
        self._state: JointState = message[2]
        frames = message[3]
        self._lock = threading.Lock()
        self._frames: list[CameraFrame] = list(frames)
        self._faults: list[Fault] = []
        self._t0: float | None = None
        self._received = time.monotonic()
        self._recording: dict[str, FloatArray] | None = None
        self._latencies: list[float] = []
        self._ended = threading.Event()
        self._send_lock = threading.Lock()
        self._receiver = threading.Thread(
            target=self._receive, name="cbp-robot-receiver", daemon=True
        )
        self._receiver.start()

    @property
    def pid(self) -> int | None:
        """The robot's process id."""
        return int(self._process.pid) if self._process.pid is not None else None

    @property
    def limits(self) -> JointLimits:
        """The limits commands are held to."""
        return self._limits

    def start(self) -> None:
        """Start the robot's clock: from now on it runs in real time."""
        if self._t0 is None:
            self._t0 = self._received = time.monotonic()
            self._post(("start", self._t0))

    def now(self) -> float:
        """The robot's clock [s] (0 until :meth:`start`).

        The simulated time its last state was measured at, carried forward
        by the wall clock for at most two of its state periods: a robot the
        machine cannot keep at the wall clock's pace (a ``lag`` fault) runs
        slower, and so does the run.
        """
        if self._t0 is None:
            return 0.0
        with self._lock:
            stamp, received = self._state.stamp, self._received
        return stamp + min(time.monotonic() - received, 2.0 * STATE_EVERY)

    def state(self) -> JointState:
        """The newest state the robot sent."""
        with self._lock:
            return self._state

    def send(self, command: Command) -> None:
        """Send ``command`` to the robot."""
        self._post(("command", command))

    def frames(self) -> list[CameraFrame]:
        """The frames received since the last call, oldest first."""
        with self._lock:
            frames, self._frames = self._frames, []
        return frames

    def faults(self) -> list[Fault]:
        """The faults received since the last call, oldest first."""
        with self._lock:
            faults, self._faults = self._faults, []
        return faults

    def brake(self) -> None:
        """Tell the robot to brake."""
        self._post(("brake",))

    def stop(self) -> None:
        """Tell the robot to brake and take no more commands."""
        self._post(("stop",))

    @property
    def latencies(self) -> list[float]:
        """Per command that carried a frame's capture time, capture to arrival [s]."""
        return self._latencies

    def recording(self) -> dict[str, FloatArray]:
        """End the robot; return what it recorded."""
        self.close()
        if self._recording is None:
            raise RuntimeError("the robot's process ended without its recording")
        return self._recording

    def close(self) -> None:
        """End the robot's process (its recording comes back first)."""
        if self._process.is_alive():
            self._post(("close",))
            self._ended.wait(30.0)
            self._process.join(10.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()
        with contextlib.suppress(OSError):
            self._conn.close()

    def _post(self, message: tuple[Any, ...]) -> None:
        with self._send_lock, contextlib.suppress(OSError, BrokenPipeError):
            self._conn.send(message)

    def _receive(self) -> None:
        conn = self._conn
        while True:
            try:
                message = conn.recv()
            except (EOFError, OSError):
                break
            kind = message[0]
            with self._lock:
                if kind == "state":
                    self._state = message[1]
                    self._received = time.monotonic()
                    self._frames.extend(message[2])
                    self._faults.extend(message[3])
                elif kind == "recording":
                    self._recording, self._latencies = message[1], message[2]
                    break
        self._ended.set()


def _context() -> Any:
    """``forkserver`` (this module preloaded in the server) where there is one.

    Not ``fork``: the controller's threads (the map's receiver, numba's) would
    be copied mid-flight.
    """
    if "forkserver" not in mp.get_all_start_methods():
        return mp.get_context("spawn")
    context = mp.get_context("forkserver")
    context.set_forkserver_preload([__name__, "cbp.driver.simulated"])
    return context


# ---------------------------------------------------------------------- the child


def _child(setup: RobotSetup, conn: Connection) -> None:
    """The robot's process: build the simulation, then run it in real time."""
    from cbp.driver.simulated import SimulatedRobot
    from cbp.sim.simulation import Simulation

    try:
        sim = Simulation(
            setup.robot,
            setup.objects,
            setup.q0,
            setup.settings,
            setup.folder,
            simulator=setup.simulator,
        )
        robot = SimulatedRobot(sim, setup.cameras, setup.timeout)
    except Exception as exc:  # said to the parent, which raises it
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    conn.send(("ready", robot.limits, robot.state(), robot.frames()))
    try:
        _RealTime(robot, conn, setup).run()
    finally:
        robot.close()


class _RealTime:
    """The robot's real-time loop: physics in slices, commands read between them."""

    def __init__(self, robot: Any, conn: Connection, setup: RobotSetup) -> None:
        self.robot, self.conn, self.setup = robot, conn, setup
        self.t0: float | None = None
        #: When the controller was found gone (its pipe closed) [s].
        self.orphaned: float | None = None
        self.next_state = 0.0
        self.lagging = False
        self.next_lag = 0.0
        #: Every fault the robot reported.
        self.said: list[Fault] = []

    def run(self) -> None:
        robot = self.robot
        while True:
            if not self._read():
                return  # closed: the recording went back
            if self.t0 is None:
                if self.orphaned is not None:
                    return  # never started: nothing moved

                time.sleep(SLICE)
                continue
            now = time.monotonic() - self.t0
            self._keep_pace(now)
            robot.advance(min(now, robot.now() + SLICE))
            if robot.now() >= self.next_state:
                self.next_state = robot.now() + STATE_EVERY
                faults = robot.faults()
                self.said.extend(faults)
                self._post(("state", robot.state(), robot.frames(), faults))
            if self.orphaned is not None and self._rested_since(self.orphaned):
                self._write_recording()
                return
            # Sleep until the next physics step falls due.
            due = robot.now() + robot.sim.dt - (time.monotonic() - self.t0)
            if due > 0:
                time.sleep(due)

    def _read(self) -> bool:
        """Take the messages waiting; False once told to close."""
        robot = self.robot
        try:
            while self.conn.poll():
                message = self.conn.recv()
                kind = message[0]
                if kind == "command":
                    robot.send(message[1])
                elif kind == "start":
                    self.t0 = message[1]
                elif kind == "brake":
                    robot.brake()
                elif kind == "stop":
                    robot.stop()
                elif kind == "close":
                    self._post(("recording", robot.recording(), robot.latencies))
                    return False
        except (EOFError, OSError):
            # The controller is gone: the watchdog brakes the arm.
            if self.orphaned is None:
                self.orphaned = robot.now()
        return True

    def _keep_pace(self, now: float) -> None:
        """Say when the physics falls behind the wall clock (at most once a second)."""
        behind = now - self.robot.now()
        if behind > LAG_LIMIT and not self.lagging and now >= self.next_lag:
            self.lagging = True
            self.next_lag = now + 1.0
            self.robot.report(
                "lag",
                f"the simulated robot is {behind * 1e3:.0f} ms behind the wall "
                "clock: the machine is too busy for it",
            )
        elif behind < 0.5 * LAG_LIMIT:
            self.lagging = False

    def _rested_since(self, orphaned: float) -> bool:
        """Whether the arm has rested ORPHAN_HOLD since its controller died."""
        robot = self.robot
        since = max(orphaned, robot.followed().end_time)
        at_rest = float(np.max(np.abs(robot.sim.v))) < REST_SPEED
        return bool(robot.now() - since > ORPHAN_HOLD and at_rest)

    def _write_recording(self) -> None:
        """Write the recording, the clock's epoch and the watchdog's trip time."""
        path = self.setup.record
        if path is None:
            return
        part = path.with_name(path.stem + ".part.npz")
        np.savez(
            part,
            t0=np.array(self.t0),
            orphaned=np.array(self.orphaned),
            stale_at=np.array(
                [f.stamp for f in self.said if f.kind == "stale_command"]
            ),
            **self.robot.recording(),
        )
        os.replace(part, path)
        print(f"cbp: the controller is gone; the robot braked and wrote {path}")

    def _post(self, message: tuple[Any, ...]) -> None:
        with contextlib.suppress(OSError, BrokenPipeError):
            self.conn.send(message)
