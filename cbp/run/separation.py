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
"""

from __future__ import annotations

import numpy as np

from cbp.collision.world import CollisionWorld
from cbp.perception.moving import MovingCellsEnvironment
from cbp.robot import FloatArray
from cbp.run.events import RunLog
from cbp.state import RobotState

__all__ = ["SeparationMonitor"]

#: The separation is restored when it is this much beyond the one needed [m]
#: (a separation at the edge says so once, not at every period).
RESTORED_BEYOND = 0.01


class SeparationMonitor:
    """Watches the separation between the robot and the moving cells of the map.

    Args:
        world: the collision world the map publishes to.
        log: where the events go.
        speed: the assumed speed of moving obstacles [m/s] (for the message).
    """

    def __init__(self, world: CollisionWorld, log: RunLog, speed: float) -> None:
        """Nothing near yet."""
        self._world = world
        self._log = log
        self._speed = speed
        self._state = RobotState(world.geometry.robot)
        #: Whether the separation is short now.
        self.short = False
        #: How many times it became short.
        self.times_short = 0

    def check(self, t: float, q: FloatArray) -> None:
        """Measure at the robot's configuration ``q`` at time ``t`` [s]."""
        world = self._world
        env = world.environment
        if not isinstance(env, MovingCellsEnvironment):
            self._restored(t)
            return
        self._state.update(q)
        placed = world.placed_apart(self._state)
        contacts = env.moving.query(
            placed, world.margin(env) + env.growth, world.settings.contacts_per_link
        )
        # The padded shapes' distances, as the constraints see them.
        distance = contacts.distance - world.padding - env.resolution
        nearest = float(np.min(distance)) if len(distance) else np.inf
        if nearest >= env.growth + (RESTORED_BEYOND if self.short else 0.0):
            self._restored(t)
            return
        if self.short:
            return
        self.short = True
        self.times_short += 1
        k = int(np.argmin(distance))
        link = world.geometry.shapes[int(contacts.shape[k])].link
        self._log.event(
            t,
            f"an obstacle the cameras see moving is {100 * max(0.0, distance[k]):.1f}"
            f" cm from {link}, nearer than the {100 * env.growth:.1f} cm the arm"
            f" needs to get away from one at {100 * self._speed:.0f} cm/s"
            " (perception.moving_speed): retreating at the arm's limits, space no"
            " camera has seen gives way; contact is possible",
        )

    def _restored(self, t: float) -> None:
        if self.short:
            self.short = False
            self._log.event(t, "moving obstacles are clear of the arm again")
