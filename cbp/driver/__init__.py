# SPDX-License-Identifier: Apache-2.0
"""The seam between the controller and a robot: what a driver for an arm meets.

Everything the controller knows of a robot crosses this seam as values with
time stamps on the robot's clock, as a real arm's interface gives them:

- :class:`JointState`: the measured joint positions and velocities, when they
  were measured (and the contact force the robot measures, where it can);
- :class:`Command`: a short timed joint trajectory to follow (positions to
  hold, or velocities over a horizon, are trajectories too), with the time it
  was sent; a command that only says "the controller is alive" carries none;
- :class:`CameraFrame`: a depth image with its intrinsics and pose
  (:class:`~cbp.perception.frame.DepthFrame`), the time of capture and the
  joint positions then (a camera on the arm moved with them), or why the
  capture failed;
- :class:`Fault`: what the robot did on its own (braked on a stale command,
  refused a command) and when.

:class:`RobotDriver` is the protocol a driver implements; the simulated robots
(:mod:`cbp.driver.simulated`, :mod:`cbp.driver.process`) and a hardware driver alike. On
the robot's side of the seam, :class:`Watchdog` brakes the arm when the newest
command is older than :data:`COMMAND_TIMEOUT`, and :func:`refusal` holds every
command to the robot's joint limits before it is followed.

The watchdog's limit: MoveIt Servo halts on commands older than 0.1 s, for a
stream of velocity commands at 100 Hz or more. A ``cbp`` controller commands
a trajectory once per command period (33 ms for CAT, 250 ms for MP), so it
keeps its commands fresh with a heartbeat while its loop keeps its deadlines
(:class:`cbp.run.robot_link.RobotLink`); :data:`COMMAND_TIMEOUT` is five
missed beats, 50 ms, which keeps a dead controller's arm braking within two
of CAT's command periods of its death.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal, Protocol, runtime_checkable

import numpy as np

from cbp.perception.frame import DepthFrame
from cbp.robot import FloatArray, RobotModel
from cbp.sim.trajectory import JointTrajectory

__all__ = [
    "COMMAND_TIMEOUT",
    "HEARTBEAT",
    "CameraFrame",
    "Command",
    "Fault",
    "FaultKind",
    "JointLimits",
    "JointState",
    "RobotDriver",
    "TorqueDriven",
    "Watchdog",
    "refusal",
]

#: A command older than this on the robot's clock brakes the arm [s].
COMMAND_TIMEOUT = 0.05

#: How often a live controller says it is alive [s].
HEARTBEAT = 0.01

#: Positions and velocities may pass their limits by this much (rounding of
#: a time parameterisation at the limit) before a command is refused.
LIMIT_TOLERANCE = 1e-6


@dataclass(frozen=True)
class JointState:
    """The robot's joints as measured.

    Attributes:
        stamp: when they were measured, on the robot's clock [s].
        q: joint positions (nq).
        v: joint velocities (nv).
        force: the sum of the contact forces the robot measures [N] (0 where
            it has no such sensor).
    """

    stamp: float
    q: FloatArray
    v: FloatArray
    force: float = 0.0


@dataclass(frozen=True)
class Command:
    """A joint trajectory for the robot to follow from now on, or a heartbeat.

    Attributes:
        stamp: when the controller sent it, on the robot's clock [s].
        trajectory: the motion (times on the robot's clock); None: keep
            following the last one (the controller is alive).
        source: the capture time of the newest camera frame the plan behind
            it saw [s] (None: no camera), for the capture-to-command latency.
    """

    stamp: float
    trajectory: JointTrajectory | None = None
    source: float | None = None

    @classmethod
    def positions(cls, stamp: float, q: FloatArray) -> Command:
        """Hold the joints at ``q`` from ``stamp`` on."""
        return cls(stamp, JointTrajectory.hold(stamp, q))

    @classmethod
    def velocities(
        cls, stamp: float, q: FloatArray, v: FloatArray, horizon: float
    ) -> Command:
        """Move at velocities ``v`` from ``q`` for ``horizon`` [s], then hold.

        The trajectory changes velocity at once: a driver's limits on
        acceleration apply (:func:`refusal`).
        """
        q, v = np.asarray(q, dtype=float), np.asarray(v, dtype=float)
        zero = np.zeros((2, q.size))
        positions = np.stack([q, q + horizon * v])
        velocities = np.stack([v, np.zeros_like(v)])
        return cls(
            stamp,
            JointTrajectory(
                np.array([stamp, stamp + horizon]), positions, velocities, zero
            ),
        )


@dataclass(frozen=True)
class CameraFrame:
    """A depth image as a camera captured it, or why it gave none.

    Attributes:
        camera: the camera's name.
        stamp: the time of capture, on the robot's clock [s].
        q: the robot's joint positions at capture.
        frame: the image, its intrinsics (projection) and pose (view); None
            when the capture failed.
        problem: why the capture failed (None when it did not).
    """

    camera: str
    stamp: float
    q: FloatArray
    frame: DepthFrame | None
    problem: str | None = None


#: What a robot did on its own.
FaultKind = Literal["stale_command", "refused", "stopped", "lag"]


@dataclass(frozen=True)
class Fault:
    """Something the robot did or met on its own side of the seam.

    Attributes:
        stamp: when, on the robot's clock [s].
        kind: ``stale_command`` (the watchdog braked), ``refused`` (a command
            broke a limit), ``stopped``, ``lag`` (a simulated robot fell
            behind the wall clock).
        message: what happened, for a person.
    """

    stamp: float
    kind: FaultKind
    message: str


@dataclass(frozen=True)
class JointLimits:
    """The limits a command is held to at the seam.

    Attributes:
        lower: lowest joint positions (nq).
        upper: highest joint positions (nq).
        velocity: top joint speeds (nv).
        names: the joints' names, for messages.
    """

    lower: FloatArray
    upper: FloatArray
    velocity: FloatArray
    names: tuple[str, ...] = field(default=())

    @classmethod
    def of(cls, robot: RobotModel) -> JointLimits:
        """The limits of ``robot``'s model."""
        return cls(
            robot.lower_limits.copy(),
            robot.upper_limits.copy(),
            robot.velocity_limits.copy(),
            tuple(robot.coordinate_names("v")),
        )


def refusal(command: Command, limits: JointLimits) -> str | None:
    """Why the robot refuses ``command``, or None when it may follow it.

    Every point must be finite, within the position limits and the velocity
    limits (to :data:`LIMIT_TOLERANCE`), and the trajectory must not start
    before the command was sent (the past cannot be followed).
    """
    trajectory = command.trajectory
    if trajectory is None:
        return None
    if not np.isfinite(command.stamp):
        return f"its stamp is {command.stamp}"
    for name in ("positions", "velocities", "accelerations", "times"):
        if not np.all(np.isfinite(getattr(trajectory, name))):
            return f"its {name} are not all finite"
    tol = LIMIT_TOLERANCE
    for what, values, bound, sign in (
        ("below the lower", trajectory.positions, limits.lower, -1.0),
        ("above the upper", trajectory.positions, limits.upper, 1.0),
        ("beyond the velocity", np.abs(trajectory.velocities), limits.velocity, 1.0),
    ):
        excess = sign * (values - bound) - tol
        if np.any(excess > 0):
            point, joint = np.unravel_index(int(np.argmax(excess)), excess.shape)
            name = limits.names[joint] if joint < len(limits.names) else str(joint)
            return (
                f"point {point} is {excess[point, joint] + tol:.3g} {what} limit "
                f"of {name}"
            )
    return None


class Watchdog:
    """Says when the newest command is too old to follow: the arm must brake.

    Args:
        timeout: the age at which a command is stale [s].
    """

    def __init__(self, timeout: float = COMMAND_TIMEOUT) -> None:
        """Arm with no command yet: nothing to follow, nothing stale."""
        self.timeout = timeout
        self.newest: float | None = None
        self.tripped = False

    def fed(self, stamp: float) -> None:
        """A command sent at ``stamp`` arrived."""
        self.newest = stamp if self.newest is None else max(self.newest, stamp)
        self.tripped = False

    def trips(self, now: float) -> bool:
        """True once, when the newest command turns stale at ``now``."""
        if self.tripped or self.newest is None:
            return False
        if now - self.newest > self.timeout:
            self.tripped = True
            return True
        return False


@runtime_checkable
class RobotDriver(Protocol):
    """What a robot offers the controller: state and frames in, commands out.

    Stamps are on the robot's clock (:meth:`now`), monotonic. A driver holds
    every command to :attr:`limits` (:func:`refusal`: a refused command is a
    :class:`Fault` and the arm brakes) and brakes on its own when commands go
    stale (:class:`Watchdog`).
    """

    @property
    def limits(self) -> JointLimits:
        """The limits commands are held to."""
        ...

    def now(self) -> float:
        """The robot's clock [s]."""
        ...

    def state(self) -> JointState:
        """The newest measured joint state."""
        ...

    def send(self, command: Command) -> None:
        """Follow ``command`` (or, refused, brake and report a fault)."""
        ...

    def frames(self) -> list[CameraFrame]:
        """The camera frames captured since the last call, oldest first."""
        ...

    def faults(self) -> list[Fault]:
        """What the robot did on its own since the last call, oldest first."""
        ...

    def brake(self) -> None:
        """Come to rest along the current motion as fast as the limits allow."""
        ...

    def stop(self) -> None:
        """Brake, and end: the driver takes no command after."""
        ...


@runtime_checkable
class TorqueDriven(Protocol):
    """A robot that also takes joint torques every control cycle (as a Franka's FCI).

    The torque law runs on the robot's side, in its cycle: ``(t, q, v) ->
    tau`` [s, rad, rad/s -> N m]. A robot in its own process offers none.
    """

    def set_torque_controller(
        self, controller: Callable[[float, FloatArray, FloatArray], FloatArray]
    ) -> None:
        """Drive the joints with ``controller`` every cycle from now on."""
        ...
