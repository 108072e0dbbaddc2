# SPDX-License-Identifier: Apache-2.0
"""Speed and separation: say when a moving obstacle is nearer than the arm can afford.

Speed and separation monitoring (ISO/TS 15066) keeps a protective separation
between a robot and what approaches it: the distance an obstacle at its
assumed speed covers while the robot reacts and brakes. Here the map measures
the cells the cameras see moving that far ahead
(:class:`~cbp.perception.moving.MovingCellsEnvironment`: the assumed speed
``perception.moving_speed`` times the look-ahead, two command periods and the
robot's stopping time, plus the snapshot's age), so the constraints keep the
arm that far from them and it retreats at its limits while it can. When a
moving obstacle is nonetheless nearer than that separation (it came faster
than the arm can retreat, from a side the arm cannot leave, or out of a
shadow), contact may follow: :class:`SeparationMonitor` says so at once, and
again when the separation is restored, so that a run's events tell where its
contact forces come from.

Declared objects that move are measured where they will be after the
look-ahead, along their declared velocity
(:class:`~cbp.collision.objects.PrimitiveEnvironment`);
:class:`DeclaredSeparationMonitor` says when one of them is nearer than the
arm can get away from, given its speed and how fast the arm can retreat
along the contact normal.
"""

from __future__ import annotations

import numpy as np

from cbp.collision.geometry import PlacedShapes
from cbp.collision.objects import PrimitiveEnvironment
from cbp.collision.world import CollisionWorld
from cbp.perception.moving import MovingCellsEnvironment
from cbp.robot import FloatArray
from cbp.run.events import RunLog
from cbp.state import RobotState

__all__ = ["DeclaredSeparationMonitor", "SeparationMonitor"]

#: The separation is restored when it is this much beyond the one needed [m]
#: (a separation at the edge says so once, not at every period).
RESTORED_BEYOND = 0.01


class _Monitor:
    """Whether a separation is short, said when it becomes short and when restored."""

    def __init__(self, world: CollisionWorld, log: RunLog) -> None:
        """Nothing near yet."""
        self._world = world
        self._log = log
        self._state = RobotState(world.geometry.robot)
        #: Whether the separation is short now.
        self.short = False
        #: How many times it became short.
        self.times_short = 0

    def _placed(self, q: FloatArray) -> PlacedShapes:
        self._state.update(q)
        return self._world.placed_apart(self._state)

    def _became_short(self, t: float, message: str) -> None:
        if not self.short:
            self.short = True
            self.times_short += 1
            self._log.event(t, message)

    def _restored(self, t: float) -> None:
        if self.short:
            self.short = False
            self._log.event(t, "moving obstacles are clear of the arm again")


class SeparationMonitor(_Monitor):
    """Watches the separation between the robot and the moving cells of the map.

    Args:
        world: the collision world the map publishes to.
        log: where the events go.
        speed: the assumed speed of moving obstacles [m/s] (for the message).
    """

    def __init__(self, world: CollisionWorld, log: RunLog, speed: float) -> None:
        """Nothing near yet."""
        super().__init__(world, log)
        self._speed = speed

    def check(self, t: float, q: FloatArray) -> None:
        """Measure at the robot's configuration ``q`` at time ``t`` [s]."""
        world = self._world
        env = world.environment
        if not isinstance(env, MovingCellsEnvironment):
            self._restored(t)
            return
        contacts = env.moving.query(
            self._placed(q),
            world.margin(env) + env.growth,
            world.settings.contacts_per_link,
        )
        # The padded shapes' distances, as the constraints see them.
        distance = contacts.distance - world.padding - env.resolution
        nearest = float(np.min(distance)) if len(distance) else np.inf
        if nearest >= env.growth + (RESTORED_BEYOND if self.short else 0.0):
            self._restored(t)
            return
        if self.short:
            return
        k = int(np.argmin(distance))
        link = world.geometry.shapes[int(contacts.shape[k])].link
        self._became_short(
            t,
            f"an obstacle the cameras see moving is {100 * max(0.0, distance[k]):.1f}"
            f" cm from {link}, nearer than the {100 * env.growth:.1f} cm the arm"
            f" needs to get away from one at {100 * self._speed:.0f} cm/s"
            " (perception.moving_speed): retreating at the arm's limits, space no"
            " camera has seen gives way; contact is possible",
        )


class DeclaredSeparationMonitor(_Monitor):
    """Says when a declared object comes nearer than the arm can get away from it.

    The protective separation of speed and separation monitoring: an object
    closing at speed c on the arm's nearest point covers c T while the arm
    reacts (T: ``reaction``, two command periods for a trajectory executor),
    and the arm, retreating from rest along the contact normal n at most at
    a = sum_j |n . J_j| a_max,j (J: the point's Jacobian; other constraints
    only lower it), loses c^2 / (2 a) more before it is as fast; one faster
    than the arm's top retreat sum_j |n . J_j| v_max,j is met wherever the arm
    goes. Nearer than that separation, said at once, and again when every
    moving object is beyond it.

    Args:
        world: the collision world the declared objects are kept in.
        log: where the events go.
    """

    def check(self, t: float, q: FloatArray, reaction: float) -> None:
        """Measure at the robot's configuration ``q`` at time ``t`` [s].

        ``reaction``: how long the robot takes to begin answering [s].
        """
        world = self._world
        env = world.environment
        if not isinstance(env, PrimitiveEnvironment):
            self._restored(t)
            return
        robot = world.geometry.robot
        padding, ahead = world.padding, env.look_ahead
        short: list[tuple[float, str]] = []
        clear = True
        for a in env.approaches(self._placed(q), padding + RESTORED_BEYOND):
            frame = robot.frame_id(world.geometry.shapes[a.shape].link)
            along = np.abs(a.normal @ self._state.point_jacobian(frame, a.point))
            top = float(along @ robot.velocity_limits)
            pull = float(along @ robot.acceleration_limits)
            now = a.ahead + a.closing * ahead - padding  # to the padded arm [m]
            needed = a.closing * reaction + a.closing**2 / (2.0 * max(pull, 1e-9))
            if a.closing > top or now < needed:
                why = (
                    f"faster than it can retreat ({100 * top:.0f} cm/s at the"
                    " joints' limits)"
                    if a.closing > top
                    else f"nearer than the {100 * needed:.1f} cm it needs to get away"
                )
                link = world.geometry.shapes[a.shape].link
                short.append(
                    (
                        now - needed,
                        f"object '{a.name}' comes at {100 * a.closing:.0f} cm/s"
                        f" and is {100 * max(now, 0.0):.1f} cm from {link}, {why}:"
                        " retreating at the arm's limits, contact is possible",
                    )
                )
            clear &= now >= needed + RESTORED_BEYOND
        if short:
            self._became_short(t, min(short)[1])
        elif clear:
            self._restored(t)
