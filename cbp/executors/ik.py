# SPDX-License-Identifier: Apache-2.0
"""The IK method: collision-aware inverse kinematics, joint interpolation (Sec. V-A).

Each command period (30 Hz, like CAT) the goal pose is solved for collision-free
joint angles near the current configuration (:class:`~cbp.executors.ik_search.
IkSearch`). The arm then moves toward them along a straight line in joint space,
every intermediate configuration collision-checked; the path ends before the
first configuration in collision, and where the period's time runs out (a
partial path, continued next period). With no collision-free solution the arm
stops, as the paper reports.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from cbp.errors import UnsafeStepError
from cbp.executors import run_periodic
from cbp.executors.ik_search import IkSearch
from cbp.executors.search_events import SearchEvents
from cbp.methods.settings import IkSettings
from cbp.robot import FloatArray, RobotModel
from cbp.run.budget import Budget
from cbp.run.parts import RunParts
from cbp.run.plan import Plan
from cbp.scenario.runtime import Scenario
from cbp.trace import FULL_PERIOD_NOTE, Trace

__all__ = ["IkPlanner", "guard_solution", "make_planner", "run_ik"]

#: How far past a joint limit an IK solution may end (solver tolerance) [rad or m].
LIMIT_TOLERANCE = 1e-6


class IkPlanner:
    """IK for the goal (cached per goal), then a checked joint-space line to it."""

    def __init__(self, scenario: Scenario, run: RunParts, settings: IkSettings):
        """Set up the IK search on the scenario's collision world."""
        self.settings = settings
        self.search = IkSearch(scenario.robot, run.ee_frame, run.world, settings.search)
        self.events = SearchEvents("ik")

    def plan(
        self, q: FloatArray, goal: pin.SE3 | None, budget: Budget, run: RunParts
    ) -> Plan:
        """Solve (if the goal changed), then interpolate toward the solution."""
        if goal is None:
            return Plan(None, 0, "no goal yet")
        target = self.search.solution_for(goal, q, budget)
        if target is None:
            self.events.failed(run, goal, exhausted=not budget.spent())
            if self.events.beyond_reach(run, goal) is not None:
                return Plan(None, 0, "goal out of reach, no IK solution: the arm stops")
            return Plan(None, 0, "no collision-free IK solution: the arm stops")
        self.events.solved(run)
        guard_solution(self.search.robot, target)
        return interpolate_checked(
            q, target, self.settings.interpolation_step, self.search, budget
        )

    def close(self) -> None:
        """The run ends: a failure still going on says how long it lasted."""
        self.events.close()


def guard_solution(robot: RobotModel, target: FloatArray) -> None:
    """The IK method's step guard: a solution the arm may be sent toward.

    The line from the current configuration to ``target`` is what reaches the
    robot (time-parameterized within its velocity and acceleration limits);
    it stays within the joint limits when both ends do. So ``target`` must be
    finite, of the robot's size and within the joint limits.

    Raises:
        UnsafeStepError: naming the joint and the amount; the trajectory loop
            holds the robot and records it (:mod:`cbp.run.faults`).
    """
    target = np.asarray(target, dtype=float)
    if target.shape != (robot.nq,) or not np.all(np.isfinite(target)):
        raise UnsafeStepError(f"IK solution rejected: not {robot.nq} finite values")
    lower, upper = robot.lower_limits, robot.upper_limits
    beyond = np.maximum(lower - target, target - upper)
    k = int(np.argmax(beyond))
    if beyond[k] > LIMIT_TOLERANCE:
        names = robot.coordinate_names("q")
        raise UnsafeStepError(
            f"IK solution rejected: {names[k]} would end {beyond[k]:.4g} beyond "
            f"its limits [{lower[k]:.4g}, {upper[k]:.4g}]"
        )


def interpolate_checked(
    q: FloatArray,
    target: FloatArray,
    step: float,
    search: IkSearch,
    budget: Budget,
) -> Plan:
    """A joint-space line from ``q`` toward ``target``, checked at every point.

    The points are at most ``step`` [rad] apart in every joint, and close
    enough that the unpadded links keep half the padding between them
    (:meth:`IkSearch.motion_steps`). Ends before the first configuration in
    collision, or where the budget runs out.
    """
    delta = target - q
    n = max(int(np.ceil(np.max(np.abs(delta)) / step)), search.motion_steps(q, target))
    path = [q]
    for k in range(1, n + 1):
        if budget.spent():
            return Plan(np.array(path), k - 1, FULL_PERIOD_NOTE)
        candidate = q + delta * (k / n)
        if not search.collision_free(candidate, budget):
            return Plan(np.array(path), k, "collision ahead: the arm stops before it")
        path.append(candidate)
    return Plan(np.array(path), n, "at the IK solution")


def make_planner(scenario: Scenario, run: RunParts) -> IkPlanner:
    """The IK method's planner for ``run``, with the ``method.ik`` settings."""
    return IkPlanner(scenario, run, scenario.spec.method.settings(IkSettings))


def run_ik(scenario: Scenario, gui: bool = False) -> Trace:
    """Run ``scenario`` with the IK method; return the trace."""
    return run_periodic(scenario, "ik", gui)
