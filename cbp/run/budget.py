# SPDX-License-Identifier: Apache-2.0
"""Planning budgets in wall-clock time or in counted work (``timing.clock``).

Each command period a trajectory executor gives its planner a :class:`Budget`.
The planner charges its work to it (:meth:`Budget.charge`: a QP step, an IK
iteration, a collision check, a trajectory point) and stops when
:meth:`Budget.spent` says so; the loop reads :meth:`Budget.elapsed` as the
period's computation time (deadline misses, the adaptive period).

* ``wall`` (the default for ``cbp run`` and, later, teleoperation): the budget is
  wall-clock time, as on a real robot; charges are ignored. Results depend on the
  machine and its load.
* ``virtual`` (the default for ``cbp sweep``): time is the sum of the charges,
  each at the cost :class:`VirtualCosts` assigns to its kind of work. The same
  scenario gives the same steps, the same trajectory and the same metrics on any
  machine and under any load, and the run goes as fast as the computer can.

The costs' defaults were measured on the 2-core machines this project is
developed on (``benchmarks/virtual_clock.py`` measures them again and prints
the ratio of each to its default).
"""

from __future__ import annotations

import time
from typing import Protocol

from cbp.methods.settings import ClockKind, VirtualCosts, Work

__all__ = [
    "Budget",
    "ClockKind",
    "VirtualBudget",
    "VirtualCosts",
    "WallBudget",
    "Work",
    "make_budget",
]


class Budget(Protocol):
    """A period's planning budget (see the module docstring)."""

    #: How long the path planned within this budget is followed [s]: the
    #: command period (the next plan replaces it then).
    horizon: float

    def charge(self, work: Work, count: int = 1) -> None:
        """Count ``count`` units of ``work`` (a virtual budget advances its time)."""

    def spent(self) -> bool:
        """Whether the budget is used up: the planner returns what it has."""

    def elapsed(self) -> float:
        """Time used since the period's computation started [s]."""

    def left(self) -> float:
        """Budget left [s] (negative once overrun)."""

    def fits(self, work: Work) -> int | None:
        """How many more units of ``work`` fit in the budget (None: not known yet)."""


class WallBudget:
    """A budget of wall-clock seconds from now.

    Charges time the work: a unit of work that would end past the deadline,
    at the cost of the last one of its kind, is not begun (:meth:`spent`).
    On a loaded machine a QP step can cost a tenth of the period; begun at
    the deadline, it overran the period, and the whole plan was discarded.
    """

    def __init__(self, seconds: float, horizon: float = 0.0) -> None:
        """Start the clock."""
        self.start = time.perf_counter()
        self.seconds = seconds
        self.horizon = horizon
        self._mark = self.start
        #: The longest a unit of any kind took at its last charge [s].
        self._unit: dict[Work, float] = {}
        self._next = 0.0

    def charge(self, work: Work, count: int = 1) -> None:
        """Time the work done since the last charge, per unit."""
        now = time.perf_counter()
        self._unit[work] = (now - self._mark) / max(count, 1)
        self._mark = now
        self._next = max(self._unit.values())

    def spent(self) -> bool:
        """The next unit of work would end past the deadline."""
        return time.perf_counter() - self.start + self._next >= self.seconds

    def elapsed(self) -> float:
        """Wall time since the start [s]."""
        return time.perf_counter() - self.start

    def left(self) -> float:
        """Seconds to the deadline."""
        return self.seconds - self.elapsed()

    def fits(self, work: Work) -> int | None:
        """Units that fit at the last one's cost; None before the first."""
        unit = self._unit.get(work)
        if unit is None or not unit > 0.0:
            return None
        return max(0, int(self.left() // unit))


class VirtualBudget:
    """A budget of counted work, at the costs of :class:`VirtualCosts`."""

    def __init__(
        self, seconds: float, costs: VirtualCosts, horizon: float = 0.0
    ) -> None:
        """Nothing charged yet."""
        self.seconds = seconds
        self.horizon = horizon
        self.costs = costs
        self.used = 0.0

    def charge(self, work: Work, count: int = 1) -> None:
        """Advance virtual time by the work's cost."""
        self.used += getattr(self.costs, work) * count

    def spent(self) -> bool:
        """The charged work reached the budget."""
        return self.used >= self.seconds

    def elapsed(self) -> float:
        """Charged time [s]."""
        return self.used

    def left(self) -> float:
        """Budget minus charged time [s]."""
        return self.seconds - self.used

    def fits(self, work: Work) -> int | None:
        """Units that fit at the work's cost."""
        cost = float(getattr(self.costs, work))
        if not cost > 0.0:
            return None
        return max(0, int(self.left() // cost))


def make_budget(
    kind: ClockKind, seconds: float, costs: VirtualCosts, horizon: float = 0.0
) -> Budget:
    """A new budget of ``seconds`` for a path followed ``horizon`` [s]."""
    if kind == "virtual":
        return VirtualBudget(seconds, costs, horizon)
    return WallBudget(seconds, horizon)
