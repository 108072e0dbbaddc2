# SPDX-License-Identifier: Apache-2.0
"""The planner of a live session: the method in control, switched at a period."""

from __future__ import annotations

import pinocchio as pin

from cbp.collision.contacts import ContactSet
from cbp.engine import Engine
from cbp.errors import CbpError
from cbp.executors import make_planner
from cbp.executors.clock import Budget
from cbp.executors.trajectory import Plan, Planner, StepsAnEngine
from cbp.plugin import HoldsContacts
from cbp.robot import FloatArray
from cbp.run import RunParts
from cbp.scenario import Scenario

__all__ = ["SwitchingPlanner"]


class SwitchingPlanner:
    """The selected method's planner; pausing brakes instead of planning.

    Each method's planner is made the first time it takes control and kept
    (a method switched back to resumes with its own state).

    Args:
        scenario: the session's scenario.
        parts: the run's parts.
        method: the method in control at the start.

    Attributes:
        method: the method in control.
        wanted: the method the operator chose (in control from the next
            period on).
        paused: hold the arm (it brakes on its trajectory).
    """

    def __init__(self, scenario: Scenario, parts: RunParts, method: str) -> None:
        """Make the first method's planner (one that cannot start fails here)."""
        self.scenario = scenario
        self.parts = parts
        self._planners: dict[str, Planner] = {}
        self.method = method
        self.wanted = method
        self.paused = False
        #: The contact sets last merged by :meth:`contacts`, and the result.
        self._merged: tuple[list[ContactSet], ContactSet] = ([], ContactSet.empty())
        self.planner(method)

    def planner(self, method: str) -> Planner:
        """Method ``method``'s planner (made on first use)."""
        planner = self._planners.get(method)
        if planner is None:
            planner = make_planner(method, self.scenario, self.parts)
            self._planners[method] = planner
        return planner

    def plan(
        self, q: FloatArray, goal: pin.SE3 | None, budget: Budget, run: RunParts
    ) -> Plan:
        """The selected planner's plan; a stop while paused."""
        if self.wanted != self.method:
            run.event(run.sim.t, f"method switched from {self.method} to {self.wanted}")
            self.method = self.wanted
        if self.paused:
            return Plan(None, 0, "paused", stop=True)
        return self.planner(self.method).plan(q, goal, budget, run)

    def engine(self) -> Engine | None:
        """The QP engine of the method in control, if it steps one (CAT, hybrid)."""
        planner = self._planners.get(self.method)
        return planner.engine if isinstance(planner, StepsAnEngine) else None

    def contacts(self) -> ContactSet | None:
        """The obstacle contacts the method in control's contact rows hold.

        Those of every constraint that holds contacts (``contact_normals``, a
        user's own), with the environment: not the robot's own pairs. None when
        the method has no such rows or nothing is latched yet. The same set
        object until a row latches new contacts (the page redraws on change).
        """
        engine = self.engine()
        if engine is None:
            return None
        latched: list[ContactSet] = []
        for entry in engine.entries:
            if isinstance(entry.plugin, HoldsContacts):
                try:
                    latched.append(entry.plugin.contacts)
                except CbpError:  # nothing latched yet
                    continue
        if not latched:
            return None
        last, merged = self._merged
        if len(last) != len(latched) or any(
            a is not b for a, b in zip(last, latched, strict=True)
        ):
            merged = ContactSet.concatenate([c.environment_part() for c in latched])
            self._merged = (latched, merged)
        return merged

    def close(self) -> None:
        """Close every planner made."""
        for planner in self._planners.values():
            planner.close()
