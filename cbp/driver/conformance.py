# SPDX-License-Identifier: Apache-2.0
"""The checks every robot driver passes: the seam's contract, as tests.

A driver (:class:`~cbp.driver.RobotDriver`) for a new arm is accepted when it
passes each check of :data:`CHECKS` (``tests/driver/test_conformance.py``
runs them on the simulated robots; ``docs/drivers.md`` shows how to run them
on yours). Each check takes a :class:`Bench`: the driver, a way to let the
robot's time pass, and a box the cameras see at a known place. Every check
moves the arm by at most :data:`NUDGE` on one joint from where it stands, at
a tenth of that joint's top speed, and leaves it at rest.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from cbp.driver import COMMAND_TIMEOUT, Command, JointState, RobotDriver
from cbp.robot import FloatArray
from cbp.sim.trajectory import JointTrajectory

__all__ = ["CHECKS", "NUDGE", "Bench", "KnownBox"]

#: The largest joint motion a check commands [rad or m].
NUDGE = 0.15

#: Joints slower than this are at rest [rad/s or m/s].
AT_REST = 0.01


@dataclass(frozen=True)
class KnownBox:
    """A box a camera sees, where it is known to be: the depth check's target.

    Attributes:
        camera: the camera that sees it.
        lower: the box's lowest corner in the world [m].
        upper: its highest corner [m].
        cell: how close its measured surface must be [m] (a map cell).
    """

    camera: str
    lower: FloatArray
    upper: FloatArray
    cell: float = 0.02


@dataclass(frozen=True)
class Bench:
    """A driver under test.

    Attributes:
        driver: the robot.
        wait: lets this much of the robot's time pass [s], sending nothing
            (a robot in lockstep is stepped; one that runs on its own is
            waited for).
        box: a box a camera sees (None: the driver has no camera).
        joint: the joint the checks move (an index of the velocities).
    """

    driver: RobotDriver
    wait: Callable[[float], None]
    box: KnownBox | None = None
    joint: int = 0

    def commanded(self, seconds: float, every: float = 0.01) -> None:
        """Let ``seconds`` pass while saying the controller is alive every ``every``."""
        end = self.driver.now() + seconds
        while self.driver.now() < end - 1e-9:
            self.driver.send(Command(self.driver.now()))
            self.wait(every)

    def nudge(self, duration: float, sign: float = 1.0) -> tuple[JointState, float]:
        """Move a joint by :data:`NUDGE` in ``duration``: the start, the top speed."""
        driver = self.driver
        state = driver.state()
        limits = driver.limits
        k = self.joint
        lower, upper = limits.lower[k], limits.upper[k]
        room = upper - state.q[k] if sign > 0 else state.q[k] - lower
        step = sign * min(NUDGE, 0.5 * float(room))
        target = state.q.copy()
        target[k] += step
        now = driver.now()
        times = np.array([now, now + duration])
        zero = np.zeros((2, state.v.size))
        speed = abs(step) / duration * 15.0 / 8.0  # a quintic's peak speed
        driver.send(
            Command(
                now,
                JointTrajectory(times, np.stack([state.q, target]), zero, zero.copy()),
            )
        )
        return state, speed


def _at_rest(bench: Bench) -> bool:
    return float(np.max(np.abs(bench.driver.state().v))) < AT_REST


def check_stamps(bench: Bench) -> None:
    """State stamps increase, lie on the robot's clock and are fresh."""
    driver = bench.driver
    stamps = []
    for _ in range(20):
        bench.commanded(0.01)
        state = driver.state()
        stamps.append(state.stamp)
        now = driver.now()
        assert state.stamp <= now + 1e-9, f"a state stamped {state.stamp} at {now}"
        assert now - state.stamp < COMMAND_TIMEOUT, (
            f"the state is {now - state.stamp:.3f} s old"
        )
    assert all(b >= a for a, b in itertools.pairwise(stamps)), stamps
    assert stamps[-1] > stamps[0], "the robot's clock did not move"


def check_stale_brake(bench: Bench) -> None:
    """A command left stale brakes the arm, which then stays at rest."""
    driver = bench.driver
    driver.faults()
    _, speed = bench.nudge(1.0)
    bench.commanded(0.3)  # moving, kept fresh
    moving = float(np.max(np.abs(driver.state().v)))
    assert moving > 0.2 * speed, f"the arm did not move ({moving:.3f})"
    silent_at = driver.now()
    bench.wait(0.5)  # no command: the watchdog brakes
    said = driver.faults()
    faults = [f for f in said if f.kind == "stale_command"]
    assert faults, f"no stale-command fault (faults: {said})"
    assert faults[0].stamp - silent_at <= COMMAND_TIMEOUT + 0.01, (
        f"braked {faults[0].stamp - silent_at:.3f} s after the last command"
    )
    assert _at_rest(bench), (
        f"still moving: {driver.state().v} (faults: {said + driver.faults()})"
    )
    q = driver.state().q.copy()
    bench.wait(0.3)
    assert float(np.max(np.abs(driver.state().q - q))) < 1e-3, "it moved after"


def check_stop(bench: Bench) -> None:
    """After stop the arm rests and the commands that follow are refused."""
    driver = bench.driver
    bench.nudge(1.0, sign=-1.0)
    bench.commanded(0.2)
    driver.stop()
    bench.wait(0.5)
    q = driver.state().q.copy()
    state = driver.state()
    driver.send(Command.positions(driver.now(), state.q + 0.05))
    bench.wait(0.3)
    assert float(np.max(np.abs(driver.state().q - q))) < 1e-3, "it moved after stop"
    assert _at_rest(bench)
    kinds = [f.kind for f in driver.faults()]
    assert "stopped" in kinds, kinds
    assert "refused" in kinds, kinds


def check_limits_refused(bench: Bench) -> None:
    """A command beyond a joint limit is refused at the seam, and nothing moves."""
    driver = bench.driver
    driver.faults()
    limits = driver.limits
    state = driver.state()
    beyond = state.q.copy()
    k = bench.joint
    beyond[k] = limits.upper[k] + 0.1
    now = driver.now()
    zero = np.zeros((2, state.v.size))
    driver.send(
        Command(
            now,
            JointTrajectory(
                np.array([now, now + 2.0]), np.stack([state.q, beyond]), zero, zero
            ),
        )
    )
    bench.commanded(0.3)
    refused = [f for f in driver.faults() if f.kind == "refused"]
    assert refused, "a command beyond the upper limit was not refused"
    moved = abs(float(driver.state().q[k] - state.q[k]))
    assert moved < 0.01, f"the arm moved {moved:.3f} toward a refused command"


def check_motion_within_limits(bench: Bench) -> None:
    """The arm follows a command within the velocity limits it is held to."""
    driver = bench.driver
    limits = driver.limits
    top = 0.0
    _, speed = bench.nudge(0.6)
    end = driver.now() + 0.8
    while driver.now() < end:
        bench.commanded(0.01)
        v = driver.state().v
        excess = np.abs(v) / limits.velocity
        top = max(top, float(np.max(excess)))
    assert top <= 1.0, f"a joint reached {top:.2f} of its velocity limit"
    assert speed <= float(limits.velocity[bench.joint])


def check_frame_depth(bench: Bench) -> None:
    """A camera's frame puts the known box's near face where it is, within a cell."""
    box = bench.box
    if box is None:
        return
    driver = bench.driver
    driver.frames()
    deadline = time.monotonic() + 30.0
    frame = None
    while frame is None and time.monotonic() < deadline:
        bench.commanded(0.05)
        frames = [f for f in driver.frames() if f.camera == box.camera]
        assert all(f.frame is not None for f in frames), [f.problem for f in frames]
        frame = frames[-1].frame if frames else None
    assert frame is not None, f"no frame from camera '{box.camera}'"
    points, hit = frame.points(2)
    points = points[hit]
    lower, upper = np.asarray(box.lower), np.asarray(box.upper)
    # The points seen within the box's outline as the camera sees it.
    eye = frame.position
    inside = np.all((points >= lower - box.cell) & (points <= upper + box.cell), axis=1)
    assert inside.sum() > 20, "the camera does not see the box"
    seen = points[inside]
    gap = np.maximum(lower - seen, 0.0) + np.maximum(seen - upper, 0.0)
    assert float(np.max(np.linalg.norm(gap, axis=1))) <= box.cell
    nearest = float(np.min(np.linalg.norm(seen - eye, axis=1)))
    corner = np.clip(eye, lower, upper)
    assert abs(nearest - float(np.linalg.norm(corner - eye))) <= box.cell, (
        f"the box's nearest point seen at {nearest:.3f} m, it is at "
        f"{float(np.linalg.norm(corner - eye)):.3f} m"
    )


#: Every check, by name: a driver passes them all.
CHECKS: dict[str, Callable[[Bench], None]] = {
    "stamps": check_stamps,
    "stale_brake": check_stale_brake,
    "stop": check_stop,
    "limits_refused": check_limits_refused,
    "motion_within_limits": check_motion_within_limits,
    "frame_depth": check_frame_depth,
}
