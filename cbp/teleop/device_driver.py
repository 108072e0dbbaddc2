# SPDX-License-Identifier: Apache-2.0
"""A device drives a session through its deadman.

The page (:mod:`cbp.teleop.device_link`) or the server's HID reader
(:mod:`cbp.teleop.hid_reader`) hands the device's state to a
:class:`DeviceDriver` about every 20 ms (:meth:`DeviceDriver.receive`). At each
of its steps the driver lets the latest state through only while the deadman
is held and the stream is fresh (:class:`Deadman`): then the profile turns it
into a command (:mod:`cbp.teleop.devices`, pure) that moves the goal
(:class:`GoalTarget`) or sets the user velocity (:class:`VelocityTarget`).
Releasing the deadman, or a stream silent for longer than the profile's
timeout, brakes: the goal stops where it is, the user velocity goes to zero
(the velocity executor brakes within its acceleration limits), and the
session's log gets an event.

Every time is read from the clock the driver is given (the live session's is
the wall clock its pacer follows; tests give a virtual one), so what a test
sees does not depend on how busy the machine is.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

import numpy as np

from cbp.teleop.devices import (
    DeviceState,
    command,
    deadman_held,
    move_goal,
)
from cbp.teleop.failures import Guarded
from cbp.teleop.profiles import (
    GOAL_COMPONENTS,
    VELOCITY_COMPONENTS,
    DeadmanSpec,
    InputProfile,
)

if TYPE_CHECKING:
    from cbp.robot import FloatArray
    from cbp.teleop.goal_session import TeleopSession
    from cbp.teleop.input_session import InputSession

__all__ = [
    "STEP_PERIOD",
    "USER_VELOCITY",
    "Deadman",
    "DeviceDriver",
    "GoalTarget",
    "Target",
    "VelocityTarget",
]

log = logging.getLogger(__name__)

#: The driver's step period [s] (the page sends a state about every 20 ms).
STEP_PERIOD = 0.02
#: A step moves the goal by at most this long's twist [s] (a driver that ran
#: late does not jump the goal).
MAX_STEP = 0.1
#: The plugin type whose input is the user velocity of orbit and pan object.
USER_VELOCITY = "camera_velocity"


class Deadman:
    """Lets a device through only while its deadman is held and its stream is fresh.

    Args:
        spec: what must be held.
        timeout: the longest the stream may be silent [s].

    Attributes:
        engaged: whether motion is let through (after the last :meth:`update`).
    """

    def __init__(self, spec: DeadmanSpec, timeout: float) -> None:
        """Disengaged until a fresh state holds the deadman."""
        self.spec = spec
        self.timeout = timeout
        self.engaged = False

    def update(
        self, state: DeviceState | None, received: float, now: float
    ) -> str | None:
        """Engage or disengage for the latest state; the change as an event.

        Args:
            state: the latest state received (None: none yet).
            received: when it was received [s, the driver's clock].
            now: the time now [s, the same clock].

        Returns:
            What changed, for the log (None when nothing did).
        """
        if state is None:
            why = "no device state"
        elif now - received > self.timeout:
            why = (
                f"device silent for {1e3 * (now - received):.0f} ms "
                f"(> {1e3 * self.timeout:.0f} ms): braking to a stop"
            )
        elif not deadman_held(self.spec, state):
            why = "deadman released: braking to a stop"
        else:
            why = ""
        engaged = not why
        changed = engaged != self.engaged
        self.engaged = engaged
        if not changed:
            return None
        if engaged:
            assert state is not None
            return f"deadman held: {state.device or 'the device'} drives"
        return why


class Target(Protocol):
    """What a driver moves: a goal or a user velocity."""

    def drive(self, profile: InputProfile, state: DeviceState, dt: float) -> bool:
        """Apply the state's command over ``dt``; whether anything was sent."""
        ...

    def brake(self) -> None:
        """Stop what the device moves."""
        ...

    def event(self, message: str) -> None:
        """Record ``message`` in the session's log."""
        ...


class GoalTarget:
    """A goal session's goal, moved by the device's twist.

    Args:
        session: the goal session.
    """

    def __init__(self, session: TeleopSession) -> None:
        """Drive ``session``'s goal."""
        self.session = session

    def drive(self, profile: InputProfile, state: DeviceState, dt: float) -> bool:
        """Move the latest goal by the twist for ``dt``; nothing for a zero twist.

        A goal that was rejected as malformed is not moved (send a valid one,
        or reset).
        """
        twist = command(profile.goal, state, profile.dead_band, GOAL_COMPONENTS)
        if dt <= 0.0 or not twist.any():
            return False
        position, rotation = self.session.goal.pose()
        if not (np.isfinite(position).all() and np.isfinite(rotation).all()):
            return False
        self.session.set_goal(*move_goal(position, rotation, twist, dt, profile.frame))
        return True

    def brake(self) -> None:
        """Nothing to send: the goal stays where the device left it."""

    def event(self, message: str) -> None:
        """An event in the run's log, at the simulated time."""
        parts = self.session.parts
        parts.event(parts.arm.t, message)


class VelocityTarget:
    """An input session's user velocity (orbit, pan object), set by the device.

    The active configuration's ``camera_velocity`` inputs take the command's
    components along the axes each commands.

    Args:
        session: a :class:`~cbp.teleop.InputSession`.
    """

    def __init__(self, session: InputSession) -> None:
        """Drive ``session``'s user velocity."""
        self.session = session

    def _entries(self) -> tuple[str, list[tuple[str, list[int]]]]:
        """The active configuration's user-velocity inputs and their axes."""
        config = self.session.active
        plugins = self.session.input_plugins(config)
        return config, [
            (name, list(plugin.axes))
            for name, plugin in plugins.items()
            if plugin.type_name == USER_VELOCITY
        ]

    def _send(self, velocity: FloatArray) -> bool:
        config, entries = self._entries()
        for name, axes in entries:
            self.session.set_input(name, velocity[axes], config)
        return bool(entries)

    def drive(self, profile: InputProfile, state: DeviceState, dt: float) -> bool:
        """Set the user velocity to the state's command (zero included)."""
        velocity = command(
            profile.velocity, state, profile.dead_band, VELOCITY_COMPONENTS
        )
        return self._send(velocity)

    def brake(self) -> None:
        """Zero the user velocity (the executor brakes within its limits)."""
        self._send(np.zeros(len(VELOCITY_COMPONENTS)))

    def event(self, message: str) -> None:
        """An event in the session's log."""
        self.session.event(message)


class DeviceDriver:
    """A device's stream, through the deadman, to a session.

    :meth:`receive` takes states from any thread; :meth:`step` (its own
    thread, :meth:`start`, every :data:`STEP_PERIOD`; or a test's calls)
    checks the deadman and drives the target.

    Args:
        profile: the input profile.
        target: what the device moves (:class:`GoalTarget`, :class:`VelocityTarget`).
        clock: the session's clock [s] (default: the wall clock,
            ``time.perf_counter``; tests give a virtual one).

    Attributes:
        received: states received so far.
        steps: steps taken so far.
        sent: steps that sent a command.
    """

    def __init__(
        self,
        profile: InputProfile,
        target: Target,
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        """Disengaged until a fresh state holds the deadman."""
        self.profile = profile
        self.target = target
        self.clock = clock
        self.deadman = Deadman(profile.deadman, profile.timeout)
        self._lock = threading.Lock()
        self._state: DeviceState | None = None
        self._received_at = -math.inf
        self._last_step: float | None = None
        self.received = self.steps = self.sent = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def receive(self, state: DeviceState) -> None:
        """Take the device's latest state (stamped with the clock now)."""
        now = self.clock()
        with self._lock:
            self._state = state
            self._received_at = now
            self.received += 1

    def step(self) -> bool:
        """Check the deadman and drive the target; whether a command was sent."""
        now = self.clock()
        with self._lock:
            state, received = self._state, self._received_at
        dt = 0.0 if self._last_step is None else min(now - self._last_step, MAX_STEP)
        self._last_step = now
        self.steps += 1
        change = self.deadman.update(state, received, now)
        if change is not None:
            if not self.deadman.engaged:
                self.target.brake()
            self.target.event(change)
        if not self.deadman.engaged or state is None:
            return False
        sent = self.target.drive(self.profile, state, dt)
        self.sent += sent
        return sent

    @property
    def latest(self) -> DeviceState | None:
        """The latest state received (None before the first)."""
        with self._lock:
            return self._state

    @property
    def engaged(self) -> bool:
        """Whether the device moves the session now."""
        return self.deadman.engaged

    # ------------------------------------------------------------------ thread

    def start(self) -> None:
        """Step every :data:`STEP_PERIOD` in a thread of its own."""
        from cbp.run import WallClockPacer

        def run() -> None:
            pacer = WallClockPacer(max_lag=STEP_PERIOD, wake=self._stop)
            k = 0
            step = Guarded(log, "device step")  # a device must not stop the session
            while not self._stop.is_set():
                step.call(self.step)
                k += 1
                pacer.wait_until(k * STEP_PERIOD)

        self._thread = threading.Thread(target=run, name="device", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop stepping (brake first if the device was driving)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        if self.deadman.engaged:
            self.deadman.engaged = False
            self.target.brake()
            self.target.event("device stopped: braking to a stop")
