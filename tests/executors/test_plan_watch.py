"""A plan being followed goes stale when an obstacle comes, not when a surface flickers."""

from __future__ import annotations

import numpy as np
import pytest

from cbp.collision import CollisionWorld, RobotGeometry
from cbp.collision.settings import CollisionSettings
from cbp.executors.ik_search import IkSearch
from cbp.executors.plan_watch import PlanWatch
from cbp.methods.settings import IkSearchSettings
from cbp.perception.kernels import FREE, OCCUPIED
from cbp.perception.occupancy import OccupancyGrid
from cbp.perception.spec import PerceptionSpec
from cbp.robot import RobotModel
from cbp.run.budget import VirtualBudget, VirtualCosts

SPEC = PerceptionSpec(cell_size=0.01, bounds=((-0.3, -0.6, -0.1), (1.0, 0.6, 1.0)))


def _map(geometry: RobotGeometry, top: float, box: bool = False):  # type: ignore[no-untyped-def]
    """A snapshot: free above a table whose cells reach up to ``top`` [m].

    ``box``: and an obstacle 10 cm above the table, clear of it (something new).
    """
    grid = OccupancyGrid(SPEC, geometry)
    grid.cells[:] = FREE
    z = grid.lower[2] + (np.arange(grid.shape[2]) + 0.5) * grid.cell
    grid.cells[:, :, z < top] = OCCUPIED
    if box:
        x = grid.lower[0] + (np.arange(grid.shape[0]) + 0.5) * grid.cell
        y = grid.lower[1] + (np.arange(grid.shape[1]) + 0.5) * grid.cell
        i = (x > 0.25) & (x < 0.75)
        j = (y > -0.3) & (y < 0.3)
        k = (z > top + 0.1) & (z < top + 0.16)
        grid.cells[np.ix_(i, j, k)] = OCCUPIED
    return grid.environment()


@pytest.fixture(scope="module")
def setting(robots: dict[str, RobotModel]):  # type: ignore[no-untyped-def]
    """A world over a table, and a plan whose middle grazes it at the free limit."""
    robot = robots["panda"]
    geometry = RobotGeometry(robot)
    settings = CollisionSettings(penetration_tolerance=0.002)  # configs/cat.yaml's
    world = CollisionWorld(geometry, _map(geometry, 0.0), settings)
    search = IkSearch(robot, "panda_hand", world, IkSearchSettings())
    high = robot.home()
    low = high.copy()
    low[1] += 1.8  # the shoulder forward: the hand down into the table
    low[3] += 0.3
    assert world.is_free(high)
    assert not world.is_free(low)
    a, b = 0.0, 1.0  # the last free point on the way down
    for _ in range(30):
        m = 0.5 * (a + b)
        a, b = (m, b) if world.is_free(high + m * (low - high)) else (a, m)
    graze = high + a * (low - high)
    return world, search, np.array([high, graze, high])


def test_a_surface_one_cell_nearer_does_not_make_a_plan_stale(setting) -> None:  # type: ignore[no-untyped-def]
    """The table's surface a cell higher (noise): the plan stays; a new box: stale."""
    world, search, plan = setting
    geometry = world.geometry
    budget = VirtualBudget(100.0, VirtualCosts())
    try:
        watch = PlanWatch(search)
        watch.start(plan, 0)
        assert not watch.stale(plan[0], budget)
        world.set_environment(_map(geometry, 0.01))  # the surface a cell nearer
        assert not search.collision_free(plan[1])  # the planner's rule says no
        assert not watch.stale(plan[0], budget)
        world.set_environment(_map(geometry, 0.03))  # three cells: it came
        assert watch.stale(plan[0], budget)
        world.set_environment(_map(geometry, 0.0, box=True))  # something new
        assert watch.stale(plan[0], budget)
    finally:
        world.set_environment(_map(geometry, 0.0))


def test_the_way_to_the_plans_start_may_not_get_deeper(setting) -> None:  # type: ignore[no-untyped-def]
    """A way in deeper than the planner allows is followed while it gets no deeper.

    (CAT came to rest in a snapshot where it was free; the map moved since.)
    """
    world, search, plan = setting
    geometry = world.geometry
    budget = VirtualBudget(100.0, VirtualCosts())
    deep = plan[1] + 0.05 * (plan[1] - plan[0]) / np.linalg.norm(plan[1] - plan[0])
    assert not search.collision_free(deep)
    lead = np.array([deep, plan[0], plan[0] + 0.01])
    try:
        watch = PlanWatch(search)
        watch.start(lead, 1)
        assert not watch.stale(deep, budget)
        world.set_environment(_map(geometry, 0.02))
        assert watch.stale(deep, budget)
    finally:
        world.set_environment(_map(geometry, 0.0))
