# SPDX-License-Identifier: Apache-2.0
"""How fast mapped obstacles come at the robot, from successive map snapshots.

A map knows where obstacles are, not how they move, so CAT plans against a
perceived obstacle as it is now and an obstacle pushed at the arm reaches it
before the trajectory loop answers (declared objects carry their velocity:
:class:`~cbp.collision.objects.PrimitiveEnvironment`'s ``look_ahead``).

What the map does tell: with unseen space counted as obstacle, a cell near the
robot turns into an obstacle only when something enters space a camera saw
free (a newly seen surface was unknown, an obstacle already). So the distance
from each robot shape to the map's obstacles, measured in the old and in the
new snapshot *at the same configuration*, changes only as obstacles move. An
:class:`ApproachEstimator` sums those changes per shape over a window and
reports the approach speed where the obstacles came at least two cells nearer
in it (one cell coming and going, a reading's flicker, sums to nothing; a
single cell does not count). The map updater publishes snapshots whose contact
distances are that much nearer over the executor's look-ahead, as declared
objects are measured ahead along their velocity.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from cbp.collision.contacts import ContactSet
from cbp.collision.map_environment import OccupancyEnvironment
from cbp.collision.world import CollisionWorld
from cbp.robot import FloatArray
from cbp.state import RobotState

__all__ = ["ApproachEstimator"]

#: The least approach over a window that counts as motion, in cells.
MIN_APPROACH_CELLS = 2.0


class ApproachEstimator:
    """Per robot shape, how fast the mapped obstacles approach it [m/s].

    Args:
        world: the collision world (its shapes, margin and contact count).
        window: the time the approach is summed over [s].
    """

    def __init__(self, world: CollisionWorld, window: float) -> None:
        """No snapshots seen yet."""
        if not window > 0:
            raise ValueError(f"window must be > 0 s, got {window}")
        self.world = world
        self.window = float(window)
        self.speeds = np.zeros(len(world.geometry.shapes))
        """The last estimate, per shape [m/s] (0 where nothing approaches)."""
        self._history: deque[tuple[float, FloatArray]] = deque()

    def update(
        self,
        t: float,
        state: RobotState,
        old: OccupancyEnvironment | None,
        new: OccupancyEnvironment,
    ) -> FloatArray:
        """Add the change from ``old`` to ``new`` at time ``t``; the speeds.

        Args:
            t: the time of the frames ``new`` took in [s].
            state: the robot at that time (kinematics computed): both snapshots
                are measured with the shapes there.
            old: the snapshot before (None at the first).
            new: the snapshot now (the same object: nothing changed).
        """
        n = len(self.speeds)
        nearer = np.zeros(n)
        if old is not None and new is not old:
            placed = self.world.placed_apart(state)
            margin = self.world.margin(new)
            per_shape = self.world.settings.contacts_per_link
            before = _nearest(old.query(placed, margin, per_shape), n)
            after = _nearest(new.query(placed, margin, per_shape), n)
            # Where both see an obstacle within the margin: an obstacle that
            # enters the margin has no earlier distance to compare.
            both = np.isfinite(before) & np.isfinite(after)
            nearer[both] = before[both] - after[both]
        history = self._history
        history.append((t, nearer))
        while history and history[0][0] <= t - self.window:
            history.popleft()
        total = np.sum([change for _, change in history], axis=0)
        least = MIN_APPROACH_CELLS * new.cell
        self.speeds = np.where(total >= least, total / self.window, 0.0)
        return self.speeds


def _nearest(contacts: ContactSet, n: int) -> FloatArray:
    """Per shape, its nearest contact's distance (inf without one)."""
    out = np.full(n, np.inf)
    np.minimum.at(out, contacts.shape, contacts.distance)
    return out
