# SPDX-License-Identifier: Apache-2.0
"""The MP method: global motion planning with OMPL's RRT-Connect (CAT Sec. V-B).

Each command period (a nominal 4 Hz, adaptive) the goal pose is solved for a
collision-free configuration (:class:`~cbp.executors.ik_search.IkSearch`), and
RRT-Connect plans a joint-space path to it from the point of the current
trajectory after the deadline. States are valid when no padded link penetrates
an obstacle or another link (the scenario's collision world); motions are
checked at OMPL's resolution. The path is shortened by OMPL's path simplifier
(rope shortcut and vertex reduction, or its full simplification), resampled,
timed to stop at its end and spliced in by the shared trajectory loop; while
the goal stays the same the plan is followed, not replaced. A plan that does not
finish in the budget counts as a miss, so the period grows.
"""

from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin

from cbp.executors.clock import Budget
from cbp.executors.ik_search import IkSearch
from cbp.executors.settings import MpSettings
from cbp.executors.simulated import SimulatedRun
from cbp.executors.trajectory import Plan, run_trajectory_executor
from cbp.robot import FloatArray
from cbp.scenario.runtime import Scenario
from cbp.trace import Trace

__all__ = ["MpPlanner", "run_mp"]


class MpPlanner:
    """RRT-Connect from the start point to the IK goal, then simplification."""

    def __init__(self, scenario: Scenario, run: SimulatedRun, settings: MpSettings):
        """Build the state space over the joint limits and the validity checker."""
        import ompl.base as ob
        import ompl.geometric as og
        import ompl.util as ou

        ou.setLogLevel(ou.LogLevel.LOG_WARN)
        if settings.timing.clock == "virtual":
            # Reproducible sampling: OMPL seeds every sampler from this, if it is
            # set before the process's first planner (one MP run per process).
            ou.RNG.setSeed(1)
        self.settings = settings
        robot = scenario.robot
        self.search = IkSearch(robot, run.ee_frame, run.world, settings.search)
        n = robot.nv
        self._space = ob.RealVectorStateSpace(n)
        bounds = ob.RealVectorBounds(n)
        for i in range(n):
            bounds.setLow(i, float(robot.lower_limits[i]))
            bounds.setHigh(i, float(robot.upper_limits[i]))
        self._space.setBounds(bounds)
        self._si = ob.SpaceInformation(self._space)
        self._q = np.zeros(n)
        self.checks = 0
        self._budget: Budget | None = None  # the period's, while it plans

        def valid(state: object) -> bool:
            q = self._q
            for i in range(n):
                q[i] = state[i]  # type: ignore[index]
            self.checks += 1
            return self.search.collision_free(q, self._budget)

        self._valid = valid  # kept alive: OMPL holds only a reference
        self._si.setStateValidityChecker(valid)
        self._si.setStateValidityCheckingResolution(settings.check_resolution)
        self._si.setup()
        self._og = og
        self._ob = ob
        self._simplifier = og.PathSimplifier(self._si)
        self._start = self._space.allocState()
        self._goal_state = self._space.allocState()

    @property
    def check_step(self) -> float:
        """Joint-space distance between the states OMPL checks along a motion [rad]."""
        return float(self.settings.check_resolution * self._space.getMaximumExtent())

    def close(self) -> None:
        """Release the validity checker (it refers back to this planner).

        OMPL's space information holds the Python checker, which holds this
        planner: a cycle through C++ that Python's collector cannot break.
        """
        self._si.setStateValidityChecker(_always_valid)
        self._valid = _always_valid

    def plan(
        self, q: FloatArray, goal: pin.SE3 | None, budget: Budget, run: SimulatedRun
    ) -> Plan:
        """IK for the goal, then plan and simplify within the budget."""
        if goal is None:
            return Plan(None, 0, "no goal yet")
        self._budget = budget
        try:
            return self._plan(q, goal, budget, run)
        finally:
            self._budget = None

    def _plan(
        self, q: FloatArray, goal: pin.SE3, budget: Budget, run: SimulatedRun
    ) -> Plan:
        s = self.settings
        target = self.search.solution_for(goal, q, budget)
        if target is None:
            return Plan(None, 0, "no collision-free IK solution: the arm stops")
        if np.max(np.abs(target - q)) < 1e-4:
            return Plan(None, 0, "at the goal")
        if np.max(np.abs(run.sim.trajectory.positions[-1] - target)) < 1e-9:
            # The trajectory being followed already ends at this goal: replanning
            # would only swap one random path for another.
            return Plan(None, 0, "following the plan to this goal")
        if not self.search.collision_free(q, budget):
            return Plan(None, 0, "start in collision: no plan")
        og = self._og
        setup = og.SimpleSetup(self._si)
        for i in range(q.size):
            self._start[i] = float(q[i])
            self._goal_state[i] = float(target[i])
        setup.setStartAndGoalStates(self._start, self._goal_state)
        planner = og.RRTConnect(self._si)
        if s.range > 0:
            planner.setRange(s.range)
        setup.setPlanner(planner)
        checks = self.checks
        left = budget.left()
        solved = left > 0 and bool(
            setup.solve(self._until(budget, left * (1.0 - s.simplify_fraction)))
        )
        if not solved or not setup.haveExactSolutionPath():
            return Plan(None, self.checks - checks, "no plan in time", timed_out=True)
        left = budget.left()
        path = setup.getSolutionPath()
        if left > 0:
            if s.simplify == "full":
                setup.simplifySolution(self._until(budget, left))
                path = setup.getSolutionPath()
            else:
                self._simplifier.ropeShortcutPath(path)
                self._simplifier.reduceVertices(path)
        points = _resample(self._states(path, q), s.waypoint_step)
        note = "planned"
        # Resampled points fall between the states OMPL checked; where one of them
        # touches, use OMPL's own interpolation instead: exactly the checked states.
        if not all(self.search.collision_free(p, budget) for p in points[1:]):
            path.interpolate()
            points = self._states(path, q)
            note = "planned (checked states only: a resampled point touched)"
        return Plan(points, self.checks - checks, note)

    def _until(self, budget: Budget, seconds: float) -> object:
        """OMPL's termination condition: ``seconds`` more of ``budget`` used."""
        stop_at = budget.elapsed() + seconds
        return self._ob.PlannerTerminationCondition(lambda: budget.elapsed() >= stop_at)

    @staticmethod
    def _states(path: object, q: FloatArray) -> FloatArray:
        """The path's states as rows, the first replaced by exactly ``q``."""
        states = np.array(
            [
                [path.getState(k)[i] for i in range(q.size)]  # type: ignore[attr-defined]
                for k in range(path.getStateCount())  # type: ignore[attr-defined]
            ]
        )
        states[0] = q  # exactly the start point, for continuity
        return states


def _resample(vertices: FloatArray, step: float) -> FloatArray:
    """Points along the polyline at most ``step`` apart per joint (vertices kept)."""
    points = [vertices[0]]
    for a, b in itertools.pairwise(vertices):
        n = max(1, int(np.ceil(np.max(np.abs(b - a)) / step)))
        points.extend(a + (b - a) * (k / n) for k in range(1, n + 1))
    return np.array(points)


def _always_valid(state: object) -> bool:
    return True


def run_mp(scenario: Scenario, gui: bool = False) -> Trace:
    """Run ``scenario`` with the MP method; return the trace."""
    settings = scenario.spec.method.settings(MpSettings)
    run = SimulatedRun(
        scenario, "mp", gui, needs_world=True, clock=settings.timing.clock
    )
    planner = MpPlanner(scenario, run, settings)
    try:
        return run_trajectory_executor(run, planner, settings.timing)
    finally:
        planner.close()
