# SPDX-License-Identifier: Apache-2.0
"""What a run's loop asks of a controller each command period: a :class:`Plan`.

A :class:`Planner` (CAT, IK, MP, the hybrid) returns a path of
configurations within a budget; the loop (:mod:`cbp.run.loop`) times it and
commands it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import pinocchio as pin

from cbp.engine import Engine
from cbp.robot import FloatArray
from cbp.run.budget import Budget

if TYPE_CHECKING:
    from cbp.run.parts import RunParts

__all__ = ["Plan", "Planner", "StepsAnEngine"]


@dataclass
class Plan:
    """A planner's answer for one period.

    Attributes:
        path: configurations from the start point on (the first is the start),
            or None for no motion (keep the current trajectory).
        steps: planning steps taken (QP steps, interpolation checks, ...).
        note: what ended the computation or why there is no path.
        timed_out: the planner ran out of time before it had a result (a miss:
            the period grows).
        stop: brake along the current trajectory now (no path): the robot
            comes to rest as soon as its limits allow
            (:func:`~cbp.sim.trajectory.stopping_trajectory`).
        final: the period's plan stands: a live loop plans for no goal that
            arrives before the period's end (backing out of contact).
    """

    path: FloatArray | None
    steps: int = 0
    note: str = ""
    timed_out: bool = False
    stop: bool = False
    final: bool = False


class Planner(Protocol):
    """Computes a path each command period (CAT, IK, MP, hybrid)."""

    def plan(
        self, q: FloatArray, goal: pin.SE3 | None, budget: Budget, run: RunParts
    ) -> Plan:
        """Path from ``q`` toward ``goal`` within ``budget``, charging its work."""
        ...

    def close(self) -> None:
        """Release what the planner holds (threads, processes); idempotent."""
        ...


@runtime_checkable
class StepsAnEngine(Protocol):
    """A planner that steps a QP engine (CAT, and the hybrid's CAT).

    A live page shows the contacts its contact rows hold.
    """

    @property
    def engine(self) -> Engine:
        """The engine it steps."""
        ...
