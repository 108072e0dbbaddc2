# SPDX-License-Identifier: Apache-2.0
"""The MP method: global motion planning with OMPL's RRT-Connect (CAT Sec. V-B).

Each command period (a nominal 4 Hz, adaptive) the goal pose is solved for a
collision-free configuration (:class:`~cbp.executors.ik_search.IkSearch`), and
RRT-Connect plans a joint-space path to it from the point of the current
trajectory after the deadline. States are valid when no padded link penetrates
an obstacle or another link (the scenario's collision world); motions are
checked at OMPL's resolution while planning. The path is shortened by OMPL's
path simplifier (rope shortcut and vertex reduction, or its full
simplification) and resampled; then each of its segments is checked all along,
at configurations close enough that the unpadded links keep half the padding
between them (:mod:`cbp.collision.motion`: OMPL's resolution, 0.065 rad on the
Panda, lets the hand move 5 cm between checks). A plan that touches between
its checked states is dropped and planned again (in the same period while
its budget lasts). It is timed to
stop at its end and spliced in by the shared trajectory loop; while
the goal stays the same the plan is followed, not replaced. A plan that does not
finish in the budget counts as a miss, so the period grows.

With the cameras, where the IK search finds nothing because the goal, or the
space a configuration for it needs, is unseen, MP says so and turns the
camera on the arm to it before it searches again (:mod:`cbp.executors.look`,
``method.mp.look``; the metrics count ``looks``).
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pinocchio as pin

from cbp.executors import run_periodic
from cbp.executors.ik_search import IkSearch
from cbp.executors.look import Looker
from cbp.executors.search_events import SearchEvents
from cbp.methods.settings import MpSettings, PlannerSettings
from cbp.robot import FloatArray, RobotModel
from cbp.run.budget import Budget
from cbp.run.parts import RunParts
from cbp.run.plan import Plan
from cbp.scenario.runtime import Scenario
from cbp.sim.trajectory import time_parameterize
from cbp.trace import Trace

__all__ = [
    "MpPlanner",
    "RrtConnect",
    "make_planner",
    "plan_size",
    "record_plan",
    "run_mp",
]


class RrtConnect:
    """OMPL's RRT-Connect in the joint space, with the collision world's checks.

    One plan is begun (:meth:`begin`), grown within budgets over one or several
    calls (:meth:`grow`: the trees are kept between calls), and turned into a
    checked, simplified and resampled path (:meth:`path`).

    Args:
        robot: the robot (fixed base, scalar joints).
        search: the IK search whose collision checks are the validity checker.
        settings: simplification, resolution, range and waypoint spacing.
        seeded: seed OMPL's random numbers (reproducible runs: it takes effect
            for the process's first planner only).
    """

    def __init__(
        self,
        robot: RobotModel,
        search: IkSearch,
        settings: PlannerSettings,
        seeded: bool = False,
    ) -> None:
        """Build the state space over the joint limits and the validity checker."""
        import ompl.base as ob
        import ompl.geometric as og
        import ompl.util as ou

        ou.setLogLevel(ou.LogLevel.LOG_WARN)
        if seeded:
            ou.RNG.setSeed(1)
        self.settings = settings
        self.search = search
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
        self._setup: object = None
        self._taken = False  # a path was taken from the trees begun last
        self._q_start = np.zeros(n)

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
        self._setup = None

    def begin(self, q: FloatArray, target: FloatArray) -> None:
        """Start a new plan from ``q`` to ``target`` (both collision-free)."""
        og = self._og
        setup = og.SimpleSetup(self._si)
        for i in range(q.size):
            self._start[i] = float(q[i])
            self._goal_state[i] = float(target[i])
        setup.setStartAndGoalStates(self._start, self._goal_state)
        planner = og.RRTConnect(self._si)
        if self.settings.range > 0:
            planner.setRange(self.settings.range)
        setup.setPlanner(planner)
        self._setup = setup
        self._taken = False
        self._q_start = q.copy()

    def continues(self, q: FloatArray, target: FloatArray) -> bool:
        """Whether the trees begun last are for ``q`` to ``target``, no path taken yet.

        Then :meth:`grow` goes on with them: a hard plan adds up the checks of
        several periods instead of starting over in each. Their states were
        checked against the snapshots of those periods; the path taken from
        them is checked against the current one (:meth:`path`).
        """
        if self._setup is None or self._taken:
            return False
        goal = np.array([self._goal_state[i] for i in range(q.size)])
        return bool(
            np.max(np.abs(q - self._q_start)) < 1e-9
            and np.max(np.abs(target - goal)) < 1e-9
        )

    def grow(self, budget: Budget, seconds: float) -> bool:
        """Grow the trees for ``seconds`` more of ``budget``; True once solved."""
        setup: Any = self._setup
        if setup is None:
            raise RuntimeError("RrtConnect.grow before begin")
        self._budget = budget
        try:
            solved = seconds > 0 and bool(setup.solve(self._until(budget, seconds)))
        finally:
            self._budget = None
        return solved and bool(setup.haveExactSolutionPath())

    def path(self, budget: Budget) -> tuple[FloatArray | None, str]:
        """The solved plan: simplified in what is left of ``budget``, resampled.

        Every segment of the resampled path is then checked all along
        (:meth:`IkSearch.motion_free`), whatever the budget: the robot moves
        along them. Where the simplified path touches, the path as the trees
        found it is checked and taken instead.

        Returns:
            The points (the first exactly the start) and a note; None for the
            points when a segment touches (the note says so).
        """
        setup: Any = self._setup
        s = self.settings
        q = self._q_start
        self._budget = budget
        try:
            left = budget.left()
            path = setup.getSolutionPath()
            found = self._states(path, q)
            if left > 0:
                if s.simplify == "full":
                    setup.simplifySolution(self._until(budget, left))
                    path = setup.getSolutionPath()
                else:
                    self._simplifier.ropeShortcutPath(path)
                    self._simplifier.reduceVertices(path)
            points = _resample(self._states(path, q), s.waypoint_step)
            # OMPL checked states along the segments at its resolution; the
            # robot sweeps everything between. (Falling back to OMPL's own
            # interpolation, as this did, kept the same segments.)
            if not self.search.path_free(points, budget):
                # Shortcuts graze obstacles between OMPL's checks more often
                # than the trees' short edges do: the path as found, then.
                points = _resample(found, s.waypoint_step)
                if not self.search.path_free(points, budget):
                    # These trees would give the same path again: the next
                    # plan begins anew (:meth:`continues`).
                    self._taken = True
                    return None, "the plan touches between the states OMPL checked"
        finally:
            self._budget = None
        self._taken = True  # the next plan begins anew (:meth:`continues`)
        return points, "planned"

    def solve(
        self, q: FloatArray, target: FloatArray, budget: Budget
    ) -> FloatArray | None:
        """:meth:`begin`, :meth:`grow`, :meth:`path` in ``budget`` (None: no path)."""
        self.begin(q, target)
        if not self.grow(
            budget, budget.left() * (1.0 - self.settings.simplify_fraction)
        ):
            return None
        points, _ = self.path(budget)
        return points

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


class MpPlanner:
    """RRT-Connect from the start point to the IK goal, then simplification."""

    def __init__(self, scenario: Scenario, run: RunParts, settings: MpSettings):
        """The IK search and RRT-Connect on the run's collision world."""
        self.settings = settings
        self.search = IkSearch(scenario.robot, run.ee_frame, run.world, settings.search)
        self.events = SearchEvents("mp")
        run.log.counters.update(
            plans=0.0, plan_path_length_rad=0.0, plan_duration_s=0.0
        )
        # Reproducible sampling in virtual time (one MP run per process).
        self.rrt = RrtConnect(
            scenario.robot,
            self.search,
            settings,
            seeded=settings.timing.clock == "virtual",
        )
        self.looker = Looker(scenario, run, settings, "mp")
        run.log.counters.update(looks=0.0)

    @property
    def checks(self) -> int:
        """Validity checks so far."""
        return self.rrt.checks

    @property
    def check_step(self) -> float:
        """Joint-space distance between the states OMPL checks along a motion [rad]."""
        return self.rrt.check_step

    def close(self) -> None:
        """Release OMPL's reference to the validity checker; say a failure going on."""
        try:
            self.rrt.close()
        finally:
            self.events.close()

    def plan(
        self, q: FloatArray, goal: pin.SE3 | None, budget: Budget, run: RunParts
    ) -> Plan:
        """IK for the goal, then plan and simplify within the budget."""
        if goal is None:
            return Plan(None, 0, "no goal yet")
        s = self.settings
        target = self.search.solution_for(goal, q, budget)
        if target is None:
            exhausted = not budget.spent()
            self.events.failed(run, goal, exhausted=exhausted)
            if self.looker.holding(run):
                return Plan(None, 0, "looking at the goal from the arm's camera")
            look = (
                self.looker.plan(q, goal, budget, run, self.rrt.solve)
                if (exhausted or self.looker.pending)
                and self.search.collision_free(q, budget)
                else None
            )
            if look is not None:
                run.log.counters["looks"] += 1
                return Plan(look.path, len(look.path), "to a view of what is unseen")
            return Plan(None, 0, "no collision-free IK solution: the arm stops")
        self.looker.stop()
        self.events.solved(run)
        if np.max(np.abs(target - q)) < 1e-4:
            return Plan(None, 0, "at the goal")
        if np.max(np.abs(run.arm.trajectory.positions[-1] - target)) < 1e-9:
            # The trajectory being followed already ends at this goal: replanning
            # would only swap one random path for another.
            return Plan(None, 0, "following the plan to this goal")
        if not self.search.collision_free(q, budget):
            return Plan(None, 0, "start in collision: no plan")
        checks = self.checks
        while True:
            # While the arm holds for a plan, its trees grow on from period to
            # period: a plan that takes longer than a period's budget is found.
            if not self.rrt.continues(q, target):
                self.rrt.begin(q, target)
            if not self.rrt.grow(budget, budget.left() * (1.0 - s.simplify_fraction)):
                note = "no plan in time"
                return Plan(None, self.checks - checks, note, timed_out=True)
            points, note = self.rrt.path(budget)
            if points is not None:
                break
            # A plan that touches between OMPL's states is dropped; a new tree
            # is grown while the budget lasts (the next period otherwise).
            run.event(run.arm.t, f"mp: {note}; planning again")
            if budget.spent():
                return Plan(None, self.checks - checks, note)
        record_plan(run, points, *s.timing.limits(self.search.robot))
        return Plan(points, self.checks - checks, note)


def record_plan(
    run: RunParts, points: FloatArray, vmax: FloatArray, amax: FloatArray
) -> tuple[float, float]:
    """Count a global plan in the run's metrics; return its length and duration.

    ``plans``, ``plan_path_length_rad`` (joint-space length) and
    ``plan_duration_s`` (timed from rest within ``vmax`` and ``amax``) add up
    over the run.
    """
    length, duration = plan_size(points, vmax, amax)
    counters = run.log.counters
    counters["plans"] = counters.get("plans", 0.0) + 1
    counters["plan_path_length_rad"] = (
        counters.get("plan_path_length_rad", 0.0) + length
    )
    counters["plan_duration_s"] = counters.get("plan_duration_s", 0.0) + duration
    return length, duration


def plan_size(
    points: FloatArray, vmax: FloatArray, amax: FloatArray
) -> tuple[float, float]:
    """A path's joint-space length [rad] and duration [s] (timed from rest)."""
    zeros = np.zeros(points.shape[1])
    timed = time_parameterize(points, 0.0, zeros, zeros, vmax, amax)
    length = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
    return length, timed.end_time if timed is not None else float("nan")


def _resample(vertices: FloatArray, step: float) -> FloatArray:
    """Points along the polyline at most ``step`` apart per joint (vertices kept)."""
    points = [vertices[0]]
    for a, b in itertools.pairwise(vertices):
        n = max(1, int(np.ceil(np.max(np.abs(b - a)) / step)))
        points.extend(a + (b - a) * (k / n) for k in range(1, n + 1))
    return np.array(points)


def _always_valid(state: object) -> bool:
    return True


def make_planner(scenario: Scenario, run: RunParts) -> MpPlanner:
    """The MP method's planner for ``run`` (``method.mp``); close it after."""
    return MpPlanner(scenario, run, scenario.spec.method.settings(MpSettings))


def run_mp(scenario: Scenario, gui: bool = False) -> Trace:
    """Run ``scenario`` with the MP method; return the trace."""
    return run_periodic(scenario, "mp", gui)
