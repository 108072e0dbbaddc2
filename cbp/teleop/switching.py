# SPDX-License-Identifier: Apache-2.0
"""The planner of a live session: the method in control, switched at a period."""

from __future__ import annotations

import time

import pinocchio as pin

from cbp.collision.contacts import ContactSet
from cbp.engine import Engine
from cbp.errors import CbpError
from cbp.executors import make_planner
from cbp.plugin import HoldsContacts
from cbp.robot import FloatArray
from cbp.run import RunParts
from cbp.run.budget import Budget
from cbp.run.plan import Plan, Planner, StepsAnEngine
from cbp.scenario import Scenario

__all__ = ["SwitchingPlanner", "held_by"]


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
        held_by: what held the arm at the last step of the last plan, by kind
            (:func:`held_by`); kept from one plan to the next, for a page.
    """

    def __init__(self, scenario: Scenario, parts: RunParts, method: str) -> None:
        """Make the first method's planner (one that cannot start fails here)."""
        self.scenario = scenario
        self.parts = parts
        self._planners: dict[str, Planner] = {}
        self.method = method
        self.wanted = method
        self.paused = False
        self.held_by: frozenset[str] = frozenset()
        #: When the last plan was made (``time.perf_counter()``; -inf: none).
        self.planned_at = -float("inf")
        #: The contact sets last merged by :meth:`contacts`, and the result.
        self._merged: tuple[list[ContactSet], ContactSet] = ([], ContactSet.empty())
        self.planner(method)

    def planner(self, method: str) -> Planner:
        """Method ``method``'s planner (made on first use)."""
        planner = self._planners.get(method)
        if planner is None:
            planner = make_planner(method, self.parts)
            self._planners[method] = planner
        return planner

    def plan(
        self, q: FloatArray, goal: pin.SE3 | None, budget: Budget, run: RunParts
    ) -> Plan:
        """The selected planner's plan; a stop while paused."""
        if self.wanted != self.method:
            run.event(run.arm.t, f"method switched from {self.method} to {self.wanted}")
            self.method = self.wanted
        if self.paused:
            self.held_by = frozenset()
            self.planned_at = time.perf_counter()
            return Plan(None, 0, "paused", stop=True)
        planner = self.planner(self.method)
        plan = planner.plan(q, goal, budget, run)
        self.held_by = held_by(planner)
        self.planned_at = time.perf_counter()
        return plan

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


def held_by(planner: Planner) -> frozenset[str]:
    """What held the arm at the last step of ``planner``'s last plan, by kind.

    CAT's (and hybrid's CAT's) hard entries active at its last step other than
    the step limits: ``contact`` (a row of contacts with an obstacle),
    ``self-collision`` (a row of contacts between the robot's own shapes only),
    ``joint limit`` (the robot's position limits), or the entry's name. Empty
    for a planner that does not say (IK, MP).
    """
    cat = getattr(planner, "cat", planner)  # hybrid steps a CatPlanner
    names = getattr(cat, "blocked_by", None)
    engine = getattr(cat, "engine", None)
    if not names or engine is None:
        return frozenset()
    plugins = {e.name: e.plugin for e in engine.entries}
    kinds = set()
    for name in names:
        plugin = plugins.get(name)
        if plugin is None:
            kinds.add(name)
        elif plugin.robot_limit == "position":
            kinds.add("joint limit")
        elif isinstance(plugin, HoldsContacts):
            kinds.add(_contact_kind(plugin))
        else:
            kinds.add(name)
    return frozenset(kinds)


def _contact_kind(plugin: HoldsContacts) -> str:
    """``self-collision`` for rows of the robot's own pairs only, else ``contact``."""
    try:
        others = plugin.contacts.other_shape
    except CbpError:  # nothing latched
        return "contact"
    return "self-collision" if len(others) and bool((others >= 0).all()) else "contact"
