# SPDX-License-Identifier: Apache-2.0
"""Leaving contact first: a path out of an obstacle along the contact normals.

A robot can find itself inside an obstacle: a start the scenario allows
(``robot.allow_initial_contact``), or an obstacle that came at it. No method
should plan from there as if it were free: a planner's yes-or-no checks find no
free configuration near it, and CAT's rows ask for more motion than the limits
give. So before any method plans, the run's loop backs the robot out
(:class:`LeavingContact`, :func:`back_out`): small steps that move every
penetrating witness point out along its contact normal, by damped least
squares on the contact rows n^T J dq, within the velocity and joint limits,
until the padded shapes clear the obstacles.
"""

from __future__ import annotations

import numpy as np

from cbp.collision.contacts import ContactSet
from cbp.collision.rows import contact_jacobian_rows
from cbp.collision.world import CollisionWorld
from cbp.robot import FloatArray
from cbp.run.parts import RunParts
from cbp.run.plan import Plan
from cbp.state import RobotState

__all__ = [
    "BACK_OUT_DT",
    "CLEAR",
    "MAX_POINTS",
    "LeavingContact",
    "back_out",
    "clear_padding",
    "contact_depth",
]

#: The back-out path's points are at most this far apart in time at full speed [s].
BACK_OUT_DT = 0.02

#: The padded shapes are clear of the obstacles by this much at the path's end [m].
CLEAR = 5e-4
#: Points of one back-out path at most (it is planned again next period).
MAX_POINTS = 60
#: How far one point of the path moves a contact along its normal at most [m].
STEP = 4e-3
#: Damping of the least squares (keeps steps small near singularities).
DAMPING = 1e-6


def contact_depth(world: CollisionWorld, contacts: ContactSet) -> float:
    """How deep the unpadded robot is in an obstacle (0: not in contact) [m]."""
    obstacles = contacts.environment_part()
    if not len(obstacles):
        return 0.0
    inflated = world.padding + world.environment.resolution
    return max(0.0, -float(np.min(obstacles.distance)) - inflated)


def back_out(
    world: CollisionWorld,
    q: FloatArray,
    step_bound: FloatArray,
    state: RobotState | None = None,
) -> tuple[FloatArray | None, float]:
    """A path from ``q`` out of the obstacles the robot is in contact with.

    Args:
        world: the collision world (its current environment).
        q: where the robot is.
        step_bound: the largest change of each joint between two points of the
            path (nv) [rad or m].
        state: a state of the world's robot to work in (moved to ``q``), so
            that a caller that backs out every period makes one; None: a new
            one.

    Returns:
        The path (its first point is ``q``; None when the unpadded robot
        touches no obstacle there), and the depth at ``q`` [m].
    """
    if state is None:
        state = RobotState(world.geometry.robot, q)
    else:
        state.update(q)
    # The contacts there as they are: ``query``, not ``check``, so that the
    # contacts a planner's rejected step carried over are neither counted nor
    # taken from the planner's next query.
    contacts = world.query(state)
    depth = contact_depth(world, contacts)
    if depth <= 0.0:
        return None, 0.0
    return _leave(world, q, contacts, step_bound, state)[0], depth


def clear_padding(
    world: CollisionWorld,
    q: FloatArray,
    step_bound: FloatArray,
    state: RobotState | None = None,
) -> FloatArray | None:
    """A path from ``q`` until the padded shapes clear the obstacles.

    A planner that needs a start free of contact cannot start where CAT
    rests: its contact rows hold the padded shapes at the obstacles' surface,
    a rounding error inside them. This path moves them out along the contact
    normals, as :func:`back_out` moves the unpadded robot out, by
    :data:`CLEAR`.

    Args:
        world: the collision world (its current environment).
        q: where the robot is.
        step_bound: the largest change of each joint between two points of the
            path (nv) [rad or m].
        state: a state of the world's robot to work in; None: a new one.

    Returns:
        The path (its first point is ``q``), ending where the padded shapes
        are clear of every obstacle; None when ``q`` is clear already or no
        such path was found within :data:`MAX_POINTS` points.
    """
    if state is None:
        state = RobotState(world.geometry.robot, q)
    else:
        state.update(q)
    contacts = world.query(state)
    if not np.any(contacts.environment_part().distance < 0.0):
        return None
    path, left = _leave(world, q, contacts, step_bound, state)
    return path if not np.any(left.environment_part().distance < 0.0) else None


def _leave(
    world: CollisionWorld,
    q: FloatArray,
    contacts: ContactSet,
    step_bound: FloatArray,
    state: RobotState,
) -> tuple[FloatArray, ContactSet]:
    """Steps from ``q`` (where ``state`` is) out along the contacts' normals.

    Until the padded shapes are :data:`CLEAR` of the obstacles, at most
    :data:`MAX_POINTS` points; the first point is ``q``. Returns the path and
    the contacts at its last point.
    """
    robot = world.geometry.robot
    joints = np.array([s.joint_id for s in world.geometry.shapes], dtype=np.intp)
    support = robot.support[joints]
    lower, upper = robot.lower_limits, robot.upper_limits
    path = [np.array(q, dtype=float)]
    for _ in range(MAX_POINTS):
        obstacles = contacts.environment_part()
        inside = obstacles.distance < CLEAR
        if not inside.any():
            break
        rows = np.zeros((int(np.count_nonzero(inside)), robot.nv))
        contact_jacobian_rows(
            obstacles.point[inside],
            obstacles.other_point[inside],
            obstacles.normal[inside],
            obstacles.shape[inside],
            obstacles.other_shape[inside],
            support,
            state.joint_jacobians(),
            rows,
        )
        wanted = np.minimum(CLEAR - obstacles.distance[inside], STEP)
        gram = rows @ rows.T + DAMPING * np.eye(len(rows))
        dq = rows.T @ np.linalg.solve(gram, wanted)
        largest = float(np.max(np.abs(dq) / step_bound))
        if not np.isfinite(largest) or largest == 0.0:
            break
        if largest > 1.0:
            dq /= largest
        following = robot.integrate(path[-1], dq)
        following = np.clip(following, lower, upper)
        path.append(following)
        state.update(following)
        contacts = world.query(state)
    return np.array(path), contacts


class LeavingContact:
    """Backs the robot out of an obstacle before any method plans.

    Against declared objects only: in an occupancy map, contact with cells is
    not contact with a surface (the map holds it to half a cell, and unseen
    space counts as an obstacle), and the methods' own rules handle it.
    """

    def __init__(self, run: RunParts, step_bound: FloatArray) -> None:
        """For ``run``; ``step_bound``: how far a joint moves between points."""
        self.run = run
        self.step_bound = step_bound
        self.since: float | None = None
        self._state: RobotState | None = None  # one for every period's check

    def plan(self, t: float, q: FloatArray) -> Plan | None:
        """A back-out plan from ``q``, or None when the robot touches nothing."""
        world = self.run.world
        if world is None or world.environment.resolution > 0.0:
            return None
        if self._state is None or self._state.robot is not world.geometry.robot:
            self._state = RobotState(world.geometry.robot)
        path, depth = back_out(world, q, self.step_bound, self._state)
        if path is None:
            if self.since is not None:
                self.run.event(
                    t, f"out of contact after {t - self.since:.2f} s of backing out"
                )
                self.since = None
            return None
        if self.since is None:
            self.since = t
            self.run.event(
                t,
                f"in contact with an obstacle, {depth * 1e3:.1f} mm deep: backing "
                "out along the contact normals before planning",
            )
        return Plan(path, len(path) - 1, "backing out of contact", final=True)
