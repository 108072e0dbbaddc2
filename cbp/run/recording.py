# SPDX-License-Identifier: Apache-2.0
"""A run's trace: the simulator's recording, the goals taken, and ground truth.

At the end of a simulated run, the recording (joint positions, commands and
contact forces) becomes a :class:`~cbp.trace.Trace` with the hand's pose, the
goal in force at each sample, and the clearance of the unpadded links to the
declared objects, measured where the objects were at each sample's time.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from cbp.collision.geometry import RobotGeometry
from cbp.collision.objects import PrimitiveEnvironment
from cbp.collision.world import CollisionSettings, CollisionWorld
from cbp.robot import FloatArray, RobotModel
from cbp.run.declared import DeclaredObjects
from cbp.run.events import RunLog
from cbp.run.faults import describe
from cbp.scenario.runtime import Scenario
from cbp.trace import Trace

__all__ = ["CLEARANCE_PERIOD", "CLEARANCE_RANGE", "clearance", "make_trace"]

#: Ground-truth clearance is computed every this many seconds of the recording.
CLEARANCE_PERIOD = 0.02
#: Clearances beyond this are reported as this [m].
CLEARANCE_RANGE = 0.3


def make_trace(
    scenario: Scenario,
    recording: dict[str, FloatArray],
    goal_changes: list[tuple[float, pin.SE3]],
    log: RunLog,
    aborted: str | None,
    ee_frame: str,
) -> Trace:
    """The trace of a simulated run.

    Args:
        scenario: the scenario that ran.
        recording: the simulator's recording (:meth:`Simulation.recording`).
        goal_changes: each accepted goal and its time (the goal in force at a
            sample is the latest one at or before it).
        log: the run's events, command periods and counters.
        aborted: why the run was aborted, or None.
        ee_frame: the frame that tracks the goal.

    A ground-truth clearance that cannot be computed is an event; the trace
    lists it as ``incomplete`` and has no clearance.
    """
    robot = scenario.robot
    t, q = recording["t"], recording["q"]
    incomplete = []
    try:
        ground_truth: FloatArray | None = clearance(scenario, t, q)
    except Exception as exc:  # the outputs are written without it
        ground_truth = None
        end = float(t[-1]) if t.size else 0.0
        log.event(end, f"clearance not computed: {describe(exc)}")
        incomplete.append("clearance")
    ee_p, ee_R = _frame_poses(robot, ee_frame, q)
    n = t.size
    goal_p = np.full((n, 3), np.nan)
    goal_R = np.full((n, 3, 3), np.nan)
    times = np.array([c[0] for c in goal_changes])
    for i, ti in enumerate(t):
        k = int(np.searchsorted(times, ti + 1e-9, side="right")) - 1
        if k >= 0:
            goal_p[i] = goal_changes[k][1].translation
            goal_R[i] = goal_changes[k][1].rotation
    return Trace(
        method=log.method,
        t=t,
        q=q,
        q_cmd=recording["q_cmd"],
        ee_position=ee_p,
        ee_rotation=ee_R,
        goal_position=goal_p,
        goal_rotation=goal_R,
        q_names=robot.coordinate_names("q"),
        v_names=robot.coordinate_names("v"),
        contact_force=recording["contact_force"],
        wrist_force=recording["wrist_force"],
        penetration=recording["penetration"],
        clearance=ground_truth,
        goal_change_time=float(times[1]) if times.size > 1 else None,
        periods=log.periods,
        events=log.events,
        aborted=aborted,
        counters=dict(log.counters),
        incomplete=incomplete,
    )


def _frame_poses(
    robot: RobotModel, frame: str, q: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Position (n, 3) and rotation (n, 3, 3) of ``frame`` at each row of ``q``."""
    model, data = robot.model, robot.model.createData()
    frame_id = robot.frame_id(frame)
    n = q.shape[0]
    positions = np.empty((n, 3))
    rotations = np.empty((n, 3, 3))
    for i in range(n):
        pin.framesForwardKinematics(model, data, q[i])
        M = data.oMf[frame_id]
        positions[i] = M.translation
        rotations[i] = M.rotation
    return positions, rotations


def clearance(scenario: Scenario, t: FloatArray, q: FloatArray) -> FloatArray:
    """Unpadded links to declared objects, every :data:`CLEARANCE_PERIOD` [m].

    Against the objects as they were at each sample's time; NaN between the
    samples measured, +inf with no declared object, at most
    :data:`CLEARANCE_RANGE`.
    """
    out = np.full(t.size, np.nan)
    if not scenario.spec.world.objects:
        out[:] = np.inf
        return out
    # The run's world has the same shapes (its padding is a setting, 0 here):
    # its geometry is not loaded again.
    geometry = (
        scenario.world.geometry
        if scenario.world is not None
        else RobotGeometry(
            scenario.robot, padding=0.0, attachments=scenario.attachments()
        )
    )
    settings = CollisionSettings(
        activation_distance=CLEARANCE_RANGE, self_collision=False, padding=0.0
    )
    world = CollisionWorld(
        geometry, PrimitiveEnvironment(scenario.environment_objects(0.0)), settings
    )
    objects = DeclaredObjects(scenario, world)  # where they are, no look-ahead
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
