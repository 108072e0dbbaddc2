# SPDX-License-Identifier: Apache-2.0
"""Whether the rest of a plan being followed is still free, as the world changes.

A spliced plan is not validated step by step as CAT's steps are: it was checked
all along when it was made, and each period the hybrid checks that the rest of
it is still free in the world as it is now (with cameras the map changes with
every frame). The rule, :class:`PlanWatch`:

- **The way to the plan's start** (the rest of CAT's braking trajectory, and
  the way back out of the padding when CAT came to rest within it: the
  planner needs a start free of contact) was never free by the planner's
  rule; it is stale when an obstacle is deeper in it than when it was
  spliced. Before, it was checked as the plan itself, and a fresh plan was
  "no longer free" at the first period that checked it.
- **The plan itself** is stale when a configuration on it is not free by the
  planner's rule, except, against an occupancy map, where every cell it is
  too deep in was free when the plan was made and touched a cell blocked
  then, and it is at most a cell deeper than the rule allows: a surface that
  moved by a cell. A still scene's map changes that way (a reading's noise
  moves a surface's cells in and out by a cell), and a plan that grazes a
  surface (a shortcut hugs it) was called stale 33 ms after it was made. An
  obstacle that comes is in cells that were free and clear of every blocked
  one, or more than a cell deep, within a frame or two. The padded link then
  reaches the penetration tolerance plus a cell and a half into the cells
  (inflated by half a cell), so the unpadded one keeps ``padding - tolerance
  - cell / 2`` from the face of the cell it faces (3 mm with the CAT
  configuration's padding and tolerance at 1 cm cells), and a reading lies
  on or behind that face.

Declared objects do not change while they stand still, and are checked by the
planner's rule exactly.
"""

from __future__ import annotations

import itertools

import numpy as np

from cbp.collision.map_environment import BlockedGrid
from cbp.collision.world import CollisionWorld
from cbp.executors.ik_search import IkSearch, check_work
from cbp.robot import FloatArray
from cbp.run.budget import Budget

__all__ = ["PlanWatch"]


class PlanWatch:
    """Checks the rest of a spliced plan each period (the module's rule).

    Args:
        search: the planner's checks (its world, its rule).
    """

    def __init__(self, search: IkSearch) -> None:
        """No plan watched yet."""
        self.search = search
        self._plan: FloatArray = np.zeros((0, 0))
        self._lead = 0  # points before the plan's own start
        self._depths: FloatArray = np.zeros(0)  # theirs when spliced [m]
        self._blocked: BlockedGrid | None = None  # the map's when spliced

    def start(self, plan: FloatArray, lead: int) -> None:
        """Watch ``plan``, whose first ``lead`` points lead to its own start.

        Their depths in the world as it is now are kept (they may only get
        shallower), and a map's obstacle cells.
        """
        self._plan = plan
        self._lead = lead
        world = self.search.world
        self._blocked = (
            getattr(world.environment, "blocked", None) if world is not None else None
        )
        self._depths = np.array(
            [
                world.check(p).penetration if world is not None else 0.0
                for p in plan[:lead]
            ]
        )

    def stale(self, q: FloatArray, budget: Budget) -> bool:
        """Whether the rest of the plan from the point nearest ``q`` is not free."""
        world = self.search.world
        if world is None:
            return False
        plan = self._plan
        first = int(np.argmin(np.linalg.norm(plan - q, axis=1)))
        for i in range(first, self._lead):
            budget.charge(check_work(world))
            if world.check(plan[i]).penetration > self._depths[i] + 1e-9:
                return True
        rest = plan[max(first, self._lead) :]
        if not len(rest):
            return False

        def free(p: FloatArray) -> bool:
            return self.search.collision_free(p, budget) or self._moved_surface(
                world, p, budget
            )

        if not free(rest[0]):
            return True
        return not all(
            world.motion_free(a, b, free) for a, b in itertools.pairwise(rest)
        )

    def _moved_surface(
        self, world: CollisionWorld, q: FloatArray, budget: Budget
    ) -> bool:
        """Whether ``q`` is held only by surfaces that moved a cell (the module's)."""
        before = self._blocked
        if before is None:
            return False
        budget.charge(check_work(world))
        check = world.check(q)
        cell = before.cell
        tolerance = world.settings.penetration_tolerance + world.environment.resolution
        if not check.penetration <= tolerance + cell:
            return False
        contacts = check.contacts
        distance = contacts.distance
        if contacts.lead is not None:
            distance = distance + contacts.lead
        deep = (contacts.other_shape < 0) & (-distance > tolerance)
        if not deep.any():
            return True
        # A contact's obstacle point lies on its cell's sphere toward the
        # shape: a quarter cell back along the normal is inside the cell.
        inner = contacts.other_point[deep] - 0.25 * cell * contacts.normal[deep]
        ijk = np.floor((inner - before.lower) / cell).astype(np.intp)
        mask = before.mask
        if not np.all((ijk >= 0) & (ijk < np.array(mask.shape))):
            return False  # outside the map: unknown, never a surface that moved
        for i, j, k in ijk:
            around = mask[i - (i > 0) : i + 2, j - (j > 0) : j + 2, k - (k > 0) : k + 2]
            if mask[i, j, k] or not around.any():
                return False  # blocked then (the plan was free of it), or new
        return True
