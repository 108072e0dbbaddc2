# SPDX-License-Identifier: Apache-2.0
"""The hybrid executor: CAT where it suffices, a planner where CAT stalls.

CAT (:mod:`cbp.executors.cat`, with the scenario's ``method.cat`` settings)
tracks the goal every command period. A stall detector watches what CAT
reports: when, for ``stall_time``, the goal error (at the end of each period's
path) has stopped shrinking while the goal stands (nearly) still and hard
constraints other than the step limits hold the arm (contact rows, joint
limits), CAT is stuck in a local minimum. Then, over as many command periods
as it needs (the arm holds, at rest where CAT left it; the periods' budgets
are the planner's, up to ``planning_budget`` for one goal):

1. the IK search (:class:`~cbp.executors.ik_search.IkSearch`, sweeping the
   redundant joint) looks for a collision-free configuration for the goal:
   with all joints free from the current configuration, the middle of the
   joint ranges and seeded random ones, keeping the solution nearest in time
   at the velocity limits; when none of them gives one, sweeping the redundant
   joint around the current configuration and taking its first (from a stuck
   configuration, a random start converges to a collision-free solution about
   a third of the time on the wrist-limit goal; the sweep, 1 in 30);
2. OMPL's RRT-Connect (:class:`~cbp.executors.mp.RrtConnect`) plans to it in
   the same collision world (with cameras: the same map, unseen space
   included), from where the arm is at rest;
3. the plan is simplified, resampled and handed to the trajectory loop, which
   times it within the same limits as every executor and splices it in.

While a plan runs, each period checks that the rest of it is still free in the
current world (:class:`~cbp.executors.plan_watch.PlanWatch`: against a map,
within half a cell of the planner's rule, so that a still scene's noise does
not make a fresh plan stale) and that the goal has not moved more than
``goal_moved`` from the one planned for. A plan that is no longer free is
braked on and planned again at once, from where the arm comes to rest (a
plan found counts as a search that succeeded: it is planned again however
often the world changes; before, control returned to CAT and the same goal
was never planned for again). A goal that moved, and a plan followed to its
end, return control to CAT at that period (CAT starts from the point the loop
gives it, so the motion stays continuous). Where no configuration or no plan
is found within the budget, an event says so and CAT's safe stop stays; the
same goal is searched again after ``retry_after`` (fresh random starts, a new
RRT-Connect), up to ``tries`` searches, and after that not until it moves.

With the cameras, where the IK search finds no configuration because the
goal, or the space a configuration for it needs, is unseen, the hybrid says
so and turns the camera on the arm to it first (:mod:`cbp.executors.look`):
it follows the look's motion, holds while the map takes the frames in, and
searches again from there (``planner.look``).

The metrics count ``plans`` (plans spliced in), ``planning_attempts`` (stalls
that started a search), ``looks``, and the joint-space length [rad] and
duration [s] of the plans (timed from rest).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
import pinocchio as pin

from cbp.engine import Engine
from cbp.executors import run_periodic
from cbp.executors.cat import CatPlanner
from cbp.executors.ik_search import IkSearch, check_work
from cbp.executors.look import Looker
from cbp.executors.mp import RrtConnect, plan_size, record_plan
from cbp.executors.plan_watch import PlanWatch
from cbp.methods.settings import CatSettings, HybridSettings
from cbp.robot import FloatArray
from cbp.run.backout import BACK_OUT_DT, clear_padding
from cbp.run.budget import Budget
from cbp.run.parts import RunParts
from cbp.run.plan import Plan
from cbp.scenario.runtime import Scenario
from cbp.trace import Trace

__all__ = ["HybridPlanner", "StallDetector", "make_planner", "run_hybrid"]

Mode = Literal["cat", "planning", "following"]

#: Trajectory points looked back over for a contact-free plan start.
MAX_BACKTRACK = 200


@dataclass(frozen=True)
class _Sample:
    """One CAT period, as the stall detector sees it."""

    t: float
    error: float
    goal: pin.SE3
    blocked: bool


class StallDetector:
    """Decides from CAT's periods that it is stuck (see the module docstring).

    Args:
        settings: the hybrid's thresholds.
    """

    def __init__(self, settings: HybridSettings) -> None:
        """No periods seen yet."""
        self.settings = settings
        self._samples: list[_Sample] = []

    def distance(self, a: pin.SE3, b: pin.SE3) -> float:
        """Position distance [m] + ``rotation_weight`` x angle [rad] of two poses."""
        angle = float(np.linalg.norm(pin.log3(a.rotation.T.dot(b.rotation))))
        return float(np.linalg.norm(a.translation - b.translation)) + (
            self.settings.rotation_weight * angle
        )

    def reset(self) -> None:
        """Forget the periods seen (after a plan, or when CAT moves on)."""
        self._samples = []

    def add(self, t: float, error: float, goal: pin.SE3, blocked: bool) -> bool:
        """Record CAT's period at ``t``; True when CAT counts as stalled."""
        s = self.settings
        samples = self._samples
        samples.append(_Sample(t, error, goal, blocked))
        # Keep just over stall_time of periods.
        while len(samples) > 2 and samples[1].t <= t - s.stall_time:
            samples.pop(0)
        first = samples[0]
        if t - first.t < s.stall_time - 1e-9:
            return False
        if min(x.error for x in samples) <= s.stall_error:
            return False  # reached (or nearly) at some point: not stuck
        if first.error - error >= s.stall_progress:
            return False  # still getting closer
        if any(self.distance(x.goal, goal) > s.goal_still for x in samples):
            return False  # the operator is moving the goal
        return not s.require_blocked or blocked


class HybridPlanner:
    """CAT each period; after a stall, IK + RRT-Connect over several periods."""

    def __init__(self, scenario: Scenario, run: RunParts) -> None:
        """CAT's planner, the stall detector, the IK search and RRT-Connect."""
        spec = scenario.spec.method
        self.settings = spec.settings(HybridSettings)
        # CAT steps until its budget is spent: the stall detector reads the
        # end of the path, and a path cut where it is long enough to follow
        # (``reach_periods``) ends before the local minimum it runs into.
        self.cat_settings = replace(spec.settings(CatSettings), reach_periods=0.0)
        self.cat = CatPlanner(scenario, self.cat_settings)
        self.robot = scenario.robot
        planner = self.settings.planner
        self.search = IkSearch(self.robot, run.ee_frame, run.world, planner.search)
        self.rrt = RrtConnect(
            self.robot,
            self.search,
            planner,
            seeded=self.cat_settings.timing.clock == "virtual",
        )
        self.detector = StallDetector(self.settings)
        self.watch = PlanWatch(self.search)
        self.looker = Looker(scenario, run, planner, "hybrid")
        self._look_path: FloatArray | None = None  # a look's plan, to splice
        self.frame_id = self.robot.frame_id(run.ee_frame)
        self._data = self.robot.model.createData()
        self._rng = np.random.default_rng(self.settings.seed)
        self._vmax, self._amax = self.cat_settings.timing.limits(self.robot)
        self.mode: Mode = "cat"
        self._planned_goal: pin.SE3 | None = None  # the goal last planned for
        self._start: FloatArray | None = None  # where the plan starts (at rest)
        self._attempts: list[tuple[FloatArray, int | None]] = []
        self._from: FloatArray | None = None  # resting point to the plan's start
        self._target: FloatArray | None = None
        self._nearest: FloatArray | None = None  # nearest solution found so far
        self._solved = False
        self._spent = 0.0  # planning time used for this goal [s]
        self._tries = 0  # searches started for the goal planned for
        self._gave_up_at: float | None = None  # when the last search failed
        self._plan: FloatArray | None = None  # the plan being followed
        self._taken = False  # the loop spliced it in
        self._note = ""
        run.log.counters.update(
            plans=0.0,
            planning_attempts=0.0,
            plan_path_length_rad=0.0,
            plan_duration_s=0.0,
            looks=0.0,
        )

    @property
    def engine(self) -> Engine:
        """The engine CAT steps (a live page shows its contacts)."""
        return self.cat.engine

    def close(self) -> None:
        """Release OMPL's reference to the validity checker."""
        self.rrt.close()

    # ------------------------------------------------------------------ the period

    def plan(
        self, q: FloatArray, goal: pin.SE3 | None, budget: Budget, run: RunParts
    ) -> Plan:
        """This period's path: CAT's, the planner's, or none (a plan is running)."""
        if goal is None:
            return self.cat.plan(q, goal, budget, run)
        t = run.arm.t
        if self.mode != "cat" and self._goal_moved(goal):
            run.event(
                t,
                f"hybrid: the goal moved more than {self.settings.goal_moved:g} from "
                f"the one {'planned' if self.mode == 'following' else 'being planned'}"
                " for; control returns to CAT",
            )
            self._to_cat()
        if self.mode == "planning":
            return self._planning(q, goal, budget, run)
        if self.mode == "following":
            plan = self._following(q, goal, t, budget, run)
            if plan is not None:
                return plan
        return self._tracking(q, goal, t, budget, run)

    def _tracking(
        self, q: FloatArray, goal: pin.SE3, t: float, budget: Budget, run: RunParts
    ) -> Plan:
        """CAT's period, watched by the stall detector."""
        plan = self.cat.plan(q, goal, budget, run)
        end = plan.path[-1] if plan.path is not None else q
        error = self.detector.distance(self._hand(end), goal)
        stalled = self.detector.add(t, error, goal, bool(self.cat.blocked_by))
        same = self._planned_goal is not None and not self._goal_moved(goal)
        if not same:
            self._tries = 0
        settings = self.settings
        retry = (
            self._tries < settings.tries
            and self._gave_up_at is not None
            and t - self._gave_up_at >= settings.retry_after
        )
        if stalled and (not same or retry):
            self._tries += 1
            blocked = ", ".join(sorted(self.cat.blocked_by)) or "nothing"
            run.event(
                t,
                f"hybrid: CAT stalled {error * 1e3:.0f} mm (weighted) from the goal "
                f"for {self.settings.stall_time:g} s, held by {blocked}; planning",
            )
            run.log.counters["planning_attempts"] += 1
            self._begin_planning(end, goal)
            # Brake now: the plan starts where the arm comes to rest.
            return Plan(None, plan.steps, "hybrid: stalled, braking to plan", stop=True)
        return plan

    # ------------------------------------------------------------------ planning

    def _begin_planning(self, start: FloatArray, goal: pin.SE3) -> None:
        self.mode = "planning"
        self._planned_goal = goal
        self._start = None  # where the trajectory being followed comes to rest
        robot = self.robot
        lower, upper = robot.lower_limits, robot.upper_limits
        seeds = [start.copy(), robot.middle()]
        seeds += [
            self._rng.uniform(lower, upper)
            for _ in range(max(0, self.settings.ik_seeds - 2))
        ]
        # Every seed with all joints free first (from a stuck configuration a
        # random start converges far more often than the sweep), then the
        # redundant joint's sweep around the current configuration; one by one
        # over the periods.
        self._attempts = [(seed, None) for seed in seeds]
        self._attempts += self.search.attempts(start)[1:]
        self._target = None
        self._nearest = None
        self._from = None
        self._solved = False
        self._spent = 0.0
        self._look_path = None

    def _planning(
        self, q: FloatArray, goal: pin.SE3, budget: Budget, run: RunParts
    ) -> Plan:
        """One period of the search; the plan when it is ready and the arm at rest."""
        t = run.arm.t
        if self._start is None:
            self._start = run.arm.trajectory.positions[-1].copy()
        start = self._start
        try:
            if self._target is None:
                self._search_configuration(goal, budget, run)
            if self._target is not None and not self._solved:
                left = budget.left() * (1.0 - self.settings.planner.simplify_fraction)
                self._solved = self.rrt.grow(budget, left)
            lead = self._lead_in(q, start, run)
            if self._solved and budget.left() > 0 and lead is not None:
                assert self._from is not None
                points: FloatArray | None
                if self._look_path is not None:
                    points, note = self._look_path, "to a view of the unseen goal"
                else:
                    points, note = self.rrt.path(budget)
                if points is None:
                    assert self._target is not None
                    run.event(t, f"hybrid: {note}; planning again")
                    self._solved = False
                    self.rrt.begin(self._from[-1], self._target)
                    return Plan(None, 0, f"hybrid: {note}")
                points = np.vstack([lead[:-1], self._from[:-1], points])
                return self._splice(points, len(lead) + len(self._from) - 2, note)
        finally:
            self._spent += budget.elapsed()
        if self.mode == "planning" and self._spent > self.settings.planning_budget:
            what = "configuration" if self._target is None else "plan"
            run.event(
                t,
                f"hybrid: no collision-free {what} for the goal within "
                f"{self.settings.planning_budget:g} s of planning; CAT keeps the arm "
                "where it stopped",
            )
            self._give_up(t)
        return Plan(None, 0, "hybrid: planning, the arm holds")

    def _search_configuration(
        self, goal: pin.SE3, budget: Budget, run: RunParts
    ) -> None:
        """Try the IK seeds in turn within ``budget``; begin RRT-Connect on success."""
        assert self._start is not None
        if self._from is None:
            self._from = self._free_start(run, budget)
            if self._from is None:
                run.event(
                    run.arm.t,
                    "hybrid: the arm rests within the planner's padding of an "
                    "obstacle and no way out of it is free; no plan from here",
                )
                self._give_up(run.arm.t)
                return
        while self._attempts and not budget.spent():
            seed, fixed = self._attempts.pop(0)
            found = self.search.attempt(goal, seed, fixed, budget)
            if found is not None and (
                self._nearest is None
                or self._time_to(found) < self._time_to(self._nearest)
            ):
                self._nearest = found
            # Every all-joints-free start is tried and the solution nearest in
            # time is kept: which seed converges first depends on where CAT
            # stopped, and a far one makes a long plan. The sweep holds the
            # redundant joint near its value, so its first solution is taken.
            free_starts_left = bool(self._attempts) and self._attempts[0][1] is None
            if self._nearest is not None and not free_starts_left:
                self._target = self._nearest
                self.rrt.begin(self._from[-1], self._nearest)
                return
        if not self._attempts and not budget.spent():
            look = self.looker.plan(self._from[-1], goal, budget, run, self.rrt.solve)
            if look is not None:
                self._target = look.view
                self._solved = True
                self._look_path = look.path
                return
            if self.looker.pending:
                return  # views left to try, next period
            run.event(
                run.arm.t,
                "hybrid: no collision-free configuration reaches the goal (the IK "
                "search found none from any seed); CAT keeps the arm where it stopped",
            )
            self._give_up(run.arm.t)

    def _time_to(self, q: FloatArray) -> float:
        """Shortest time [s] from the plan's start to ``q`` at the velocity limits."""
        assert self._start is not None
        return float(np.max(np.abs(q - self._start) / self._vmax))

    @staticmethod
    def _lead_in(q: FloatArray, start: FloatArray, run: RunParts) -> FloatArray | None:
        """The rest of the trajectory being followed, from ``q`` to ``start``.

        The plan is spliced at the loop's starting point ``q`` without waiting
        for the arm to come to rest: it first follows what is left of the
        (validated, stopping) trajectory to where the plan begins. None when
        ``q`` is not a point of that trajectory or it no longer ends at
        ``start``.
        """
        positions = run.arm.trajectory.positions
        if not np.array_equal(positions[-1], start):
            return None
        if np.array_equal(q, start):
            return start[None]
        match = np.flatnonzero(np.all(positions == q, axis=1))
        return positions[match[-1] :] if match.size else None

    def _free_start(self, run: RunParts, budget: Budget) -> FloatArray | None:
        """The way from the resting point to where the plan may start.

        OMPL needs a start free of contact; CAT may rest within the penetration
        tolerance of an obstacle. Then the plan starts at the last free
        configuration of the trajectory that brought the arm there, reached by
        going back along it (CAT validated those steps).

        Returns:
            The configurations from the resting point to the plan's start (one
            row when the resting point itself is free), or None.
        """
        assert self._start is not None
        if self.search.collision_free(self._start, budget):
            return self._start[None]
        came = run.arm.trajectory.positions[::-1]
        for k in range(1, min(len(came), MAX_BACKTRACK)):
            if self.search.collision_free(came[k], budget):
                return np.vstack([self._start[None], came[1 : k + 1]])
        # An arm at rest has no way back along its trajectory: out along the
        # contact normals, until the padded shapes clear the obstacles.
        world = run.world
        if world is None:
            return None
        budget.charge(check_work(world))
        out = clear_padding(world, self._start, self._vmax * BACK_OUT_DT)
        if out is not None and self.search.collision_free(out[-1], budget):
            return out
        return None

    def _splice(self, points: FloatArray, lead: int, note: str) -> Plan:
        """Hand the plan to the loop; from the next period, follow it.

        ``lead``: the points before the plan's own start (the way there from
        where the arm is, :class:`~cbp.executors.plan_watch.PlanWatch`).
        """
        self.mode = "following"
        self._plan = points
        self._taken = False
        self._note = note
        self._tries = 0  # a search that found its plan
        self.watch.start(points, lead)
        return Plan(points, self.rrt.checks, f"hybrid: {note}")

    # ------------------------------------------------------------------ following

    def _following(
        self, q: FloatArray, goal: pin.SE3, t: float, budget: Budget, run: RunParts
    ) -> Plan | None:
        """Keep following the plan (no new path), or None to give CAT the period.

        A look's plan (to a view of an unseen goal) is followed to its end and
        held there while the map takes the camera's frames in; then the search
        for the goal begins again from there.
        """
        assert self._plan is not None
        trajectory = run.arm.trajectory
        look = self._look_path is not None
        if not self._taken:
            if not np.array_equal(trajectory.positions[-1], self._plan[-1]):
                # The loop did not splice the plan (a missed deadline, or it
                # could not be timed from the arm's velocity): splice it again
                # from where the arm is along its way in, next period.
                self.mode = "planning"
                return Plan(None, 0, "hybrid: plan not taken; trying again")
            self._taken = True
            if look:
                run.log.counters["looks"] += 1
                length, duration = plan_size(self._plan, self._vmax, self._amax)
            else:
                length, duration = record_plan(run, self._plan, self._vmax, self._amax)
            run.event(
                t - self.cat_settings.timing.period,
                f"hybrid: {self._note}: {len(self._plan)} points, {length:.2f} rad, "
                f"{duration:.2f} s; following it",
            )
        if look and trajectory.end_time <= t + 1e-9:
            if self.looker.holding(run):
                return Plan(
                    None, 0, "hybrid: looking at the goal from the arm's camera"
                )
            self._begin_planning(trajectory.positions[-1], goal)
            return Plan(None, 0, "hybrid: looked; planning")
        if trajectory.end_time <= t + 1e-9:
            run.event(t, "hybrid: plan followed to its end; control returns to CAT")
            self._to_cat()
            return None
        # The rest of the plan must still be free in the world as it is now
        # (with cameras the map may have grown): else brake and plan again.
        if self.watch.stale(q, budget):
            target = self._target if self._target is not None else q
            run.event(
                t,
                "hybrid: the rest of the plan is no longer free; braking to plan again",
            )
            self._to_cat()
            run.log.counters["planning_attempts"] += 1
            self._tries += 1
            self._begin_planning(target, goal)
            return Plan(None, 0, "hybrid: plan no longer free, braking", stop=True)
        return Plan(None, 0, "hybrid: following the plan")

    def _give_up(self, t: float) -> None:
        """Back to CAT after a search that found nothing; retry later, bounded.

        The search's random starts and RRT-Connect's samples may fail where
        another try succeeds: the same goal is tried again after
        ``retry_after``, up to ``tries`` times in all.
        """
        self._gave_up_at = t
        self._to_cat()

    def _to_cat(self) -> None:
        """Back to CAT tracking; the stall detector starts afresh.

        The goal planned for is remembered: it is not planned for again until it
        moves by more than ``goal_moved``.
        """
        self.mode = "cat"
        self._plan = None
        self._target = None
        self._solved = False
        self._look_path = None
        self.looker.stop()
        self.detector.reset()

    # ------------------------------------------------------------------ helpers

    def _goal_moved(self, goal: pin.SE3) -> bool:
        planned = self._planned_goal
        return planned is not None and (
            self.detector.distance(planned, goal) > self.settings.goal_moved
        )

    def _hand(self, q: FloatArray) -> pin.SE3:
        pin.framesForwardKinematics(self.robot.model, self._data, q)
        return self._data.oMf[self.frame_id].copy()


def make_planner(scenario: Scenario, run: RunParts) -> HybridPlanner:
    """The hybrid's planner for ``run`` (``method.hybrid``); close it after."""
    return HybridPlanner(scenario, run)


def run_hybrid(scenario: Scenario, gui: bool = False) -> Trace:
    """Run ``scenario`` with the hybrid executor; return the trace."""
    return run_periodic(scenario, "hybrid", gui)
