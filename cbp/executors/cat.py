# SPDX-License-Identifier: Apache-2.0
"""The CAT executor: many validated QP steps per command period (CAT Sec. IV).

Each command period, from the starting point chosen by the trajectory loop
(:mod:`cbp.run.loop`), the engine takes QP steps toward the current
goal until the period's time budget is spent, the motion has converged, the
path reaches past what the arm could follow before the next period's plan
replaces it (``reach_periods``), or a step cannot be made. Every step is
validated against the collision world (Sec. IV-C): a step that penetrates
deeper than ``collision.penetration_tolerance`` is rejected and the contacts
found there constrain the retry. The steps form the path that the loop times
(stoppable at its end) and splices in.

The objective and constraints are the scenario's task and constraint entries:
CAT is a configuration (``scenarios/configs/cat.yaml``), not code here.
"""

from __future__ import annotations

import numba
import numpy as np
import pinocchio as pin

from cbp.errors import CbpError
from cbp.executors import run_periodic
from cbp.executors.stepping import ValidatedStepper
from cbp.methods.settings import CatSettings
from cbp.plugin import HoldsContacts
from cbp.robot import FloatArray
from cbp.run.budget import Budget
from cbp.run.parts import RunParts
from cbp.run.plan import Plan
from cbp.scenario.runtime import Scenario
from cbp.trace import FULL_PERIOD_NOTE, Trace

__all__ = ["REACHED_NOTE", "CatPlanner", "make_planner", "run_cat"]

#: A contact row within this of its bound (the safety distance) holds the arm [m].
HOLDING_DISTANCE = 0.005
#: A period's note when its path became long enough (``reach_periods``).
REACHED_NOTE = "path reaches past the next period"


class CatPlanner:
    """Sequential QP with step validation, as many steps as the budget allows."""

    def __init__(self, scenario: Scenario, settings: CatSettings) -> None:
        """One engine for the run; the scenario's collision world if it has one."""
        self.scenario = scenario
        self.settings = settings
        self.engine = scenario.make_engine()
        #: The entries that bound a step's size only (the robot's velocity
        #: and acceleration limits): not obstacles to the goal.
        self.step_limits = {
            e.name
            for e in self.engine.entries
            if e.plugin.robot_limit in ("velocity", "acceleration")
        }
        #: Hard entries other than the step limits that were active at the last
        #: step of the last period (contacts, joint limits): what holds the arm.
        self.blocked_by: set[str] = set()
        self._contact_entries = [
            (e.name, e.plugin)
            for e in self.engine.entries
            if isinstance(e.plugin, HoldsContacts)
        ]
        #: Whether unseen space held the arm at the last period, and when that
        #: was last said [s].
        self._unseen_holds = False
        self._unseen_said = -np.inf
        self._stepper: ValidatedStepper | None = None
        #: The duration of the last step taken [s] (``step_dt``, or stretched).
        self._dt = settings.step_dt
        self._vmax, amax = settings.timing.limits(scenario.robot)
        with np.errstate(divide="ignore", invalid="ignore"):  # unknown limits
            self._stop = self._vmax**2 / (2.0 * amax)

    def plan(
        self, q: FloatArray, goal: pin.SE3 | None, budget: Budget, run: RunParts
    ) -> Plan:
        """QP steps from ``q`` until the budget is spent or the motion stops."""
        s = self.settings
        if goal is None:
            return Plan(None, 0, "no goal yet")
        stepper = self._stepper
        if stepper is None:  # one per run: easings are said once per episode
            world = run.world if self.scenario.needs_collision_world else None
            stepper = self._stepper = ValidatedStepper(
                self.engine, world, run.event, lambda: run.arm.t
            )
        # A step is kept if it penetrates no deeper than the tolerance, or than
        # where it started (so a robot that starts in collision can leave it).
        stepper.start(q)
        self.blocked_by = set()
        path = [q]
        steps = rejections = still = 0
        covered = 0.0  # the path's duration at the steps' velocity bounds [s]
        note = FULL_PERIOD_NOTE
        reach = self._reach(budget.horizon)
        travel = np.zeros_like(reach)  # each joint's travel along the path
        while steps < s.max_steps:
            if budget.spent():
                break
            steps += 1
            if run.goal.changed():  # a live goal moved: steer toward it now
                run.goal.resend(run.arm.t)
            dt = self._step_dt(budget, covered)
            step = stepper.step(q, dt)
            budget.charge("qp_step")
            if step.outcome == "failed":
                note = f"QP step failed, path ends here: {step.reason}"
                run.event(run.arm.t, note)
                break
            if step.outcome == "rejected":
                rejections += 1
                if rejections >= s.max_rejections:
                    note = f"{rejections} steps rejected in a row ({step.reason})"
                    break
                continue
            rejections = 0
            q = step.q
            path.append(q)
            covered += dt
            assert step.dq is not None
            largest, reached = _walk(step.dq, travel, reach)
            if largest < s.converged_step:
                still += 1
                if still >= 3:
                    note = "converged"
                    break
            else:
                still = 0
            if reached:
                note = REACHED_NOTE
                break
        else:
            note = "max_steps reached"
        last = stepper.last
        if steps and step.dq is not None and last is not None:
            self.blocked_by = last.problem.active_entries(step.dq) - self.step_limits
        self._say_if_unseen_space_holds(run)
        return Plan(np.array(path), steps, note)

    def _reach(self, horizon: float) -> FloatArray:
        """Each joint's travel that makes the path long enough [rad or m].

        At the timing's velocity limit for ``reach_periods`` periods of
        ``horizon`` [s], then braking at its acceleration limit; infinite
        (never long enough) when ``reach_periods`` is 0 or a limit unknown.
        """
        periods = self.settings.reach_periods
        if periods <= 0.0:
            return np.full_like(self._vmax, np.inf)
        reach = self._vmax * periods * horizon + self._stop
        return np.where(np.isfinite(reach) & (reach > 0.0), reach, np.inf)

    def _step_dt(self, budget: Budget, covered: float) -> float:
        """The next step's duration: ``step_dt``, longer when few steps fit.

        The path must reach over the period it is followed for (``covered``
        of it so far [s]); when the steps that still fit in the budget, at
        the last one's cost, cannot cover the rest at ``step_dt``, each
        covers its share, up to ``max_step_stretch`` times ``step_dt``. The
        first step of a period, before any is timed, takes the last one's.
        """
        s = self.settings
        fits = budget.fits("qp_step")
        if fits is not None:
            need = budget.horizon - covered
            share = need / max(fits, 1)
            self._dt = min(max(share, s.step_dt), s.max_step_stretch * s.step_dt)
        return self._dt

    def close(self) -> None:
        """Say the easing episode under way (the engine is the run's)."""
        if self._stepper is not None:
            self._stepper.eased.flush()

    def _say_if_unseen_space_holds(self, run: RunParts) -> None:
        """An event when contacts with space no camera has seen hold the arm.

        The arm then waits for a camera to see that space, which an obstacle
        would not tell the user. Said when it starts, at most once a second.
        """
        links: list[str] = []
        nearest: FloatArray | None = None
        for name, plugin in self._contact_entries:
            if name not in self.blocked_by or plugin.world is None:
                continue
            try:
                contacts = plugin.contacts
            except CbpError:  # nothing latched
                continue
            bound = float(getattr(plugin.params, "safety_distance", 0.0))
            holding = (contacts.distance <= bound + HOLDING_DISTANCE) & (
                contacts.other_shape < 0  # not the robot's own
            )
            # A point just inside the obstacle cell, behind its witness point.
            inside = contacts.other_point - 1e-3 * contacts.normal
            unseen = holding & run.unseen(inside)
            if not unseen.any():
                continue
            shapes = plugin.world.geometry.shapes
            links += [shapes[i].link for i in contacts.shape[unseen]]
            k = np.flatnonzero(unseen)[np.argmin(contacts.distance[unseen])]
            nearest = contacts.other_point[k]
        t = run.arm.t
        started = nearest is not None and not self._unseen_holds
        self._unseen_holds = nearest is not None
        if nearest is None or not started or t - self._unseen_said < 1.0:
            return
        self._unseen_said = t
        x, y, z = nearest
        run.event(
            t,
            f"held by space no camera has seen (beside {', '.join(sorted(set(links)))};"
            f" nearest at {x:.2f}, {y:.2f}, {z:.2f} m): a camera that sees it, or"
            " perception.unknown: free, lets the arm on",
        )


@numba.njit(cache=True, nogil=True)
def _walk(dq: FloatArray, travel: FloatArray, reach: FloatArray) -> tuple[float, bool]:
    """A step along the path: its largest entry's magnitude, and whether it arrived.

    Adds each joint's ``|dq|`` to ``travel`` (in place); arrived when some
    joint's travel is at least its ``reach``. ``dq`` is finite (the step
    guard's).
    """
    largest = 0.0
    reached = False
    for i in range(dq.shape[0]):
        x = abs(dq[i])
        largest = max(largest, x)
        travel[i] += x
        reached = reached or travel[i] >= reach[i]
    return largest, reached


_walk(np.zeros(1), np.zeros(1), np.ones(1))  # compiled (or loaded from the cache)


def make_planner(scenario: Scenario, run: RunParts) -> CatPlanner:
    """CAT's planner for ``run``, with the scenario's ``method.cat`` settings."""
    return CatPlanner(scenario, scenario.spec.method.settings(CatSettings))


def run_cat(scenario: Scenario, gui: bool = False) -> Trace:
    """Run ``scenario`` with the CAT executor; return the trace."""
    return run_periodic(scenario, "cat", gui)
