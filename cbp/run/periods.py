# SPDX-License-Identifier: Apache-2.0
"""The adaptive command period, and deadline misses counted rather than listed.

After a missed deadline the period grows (``timing.growth``); after a period
that used less than half its time it shrinks (``timing.shrink``), toward the
shortest period. Left at that, a machine that cannot sustain the shortest
period oscillates: shrink, miss, grow, shrink, miss. So a miss also sets a
floor, the period that was missed grown once, which the period does not
shrink below for :data:`FLOOR_HOLD` seconds of the loop's time: the period
settles at what the machine sustains.

A miss is an event, but a run of them is not a flood of events: the first is
said at once, the next ones are counted and said together at most once per
:data:`MISS_REPORT` seconds (how many, and the longest), and once more when
the loop meets its deadlines again.
"""

from __future__ import annotations

from collections.abc import Callable

__all__ = [
    "FLOOR_HOLD",
    "MISS_REPORT",
    "DeadlineMisses",
    "LeadAdapter",
    "PeriodAdapter",
]

#: How long a missed period holds the period's floor [s of the loop's time].
FLOOR_HOLD = 2.0
#: Deadline misses are said together at most this often [s of the loop's time].
MISS_REPORT = 1.0


class _Scaled:
    """A duration kept within [``shortest``, ``longest``], scaled by a factor.

    Args:
        shortest: the shortest duration [s].
        longest: the longest duration [s].
        growth: the factor it grows by (>= 1).
        shrink: the factor it shrinks by (<= 1).
    """

    def __init__(
        self, shortest: float, longest: float, growth: float, shrink: float
    ) -> None:
        """Keep the bounds and factors."""
        self.shortest, self.longest = shortest, longest
        self.growth, self.shrink = growth, shrink

    def _grown(self, value: float) -> float:
        """``value`` grown once, at most :attr:`longest` [s]."""
        return min(value * self.growth, self.longest)

    def _shrunk(self, value: float, floor: float) -> float:
        """``value`` shrunk once, at least ``floor`` [s]."""
        return max(value * self.shrink, floor)


class PeriodAdapter(_Scaled):
    """The next command period from how the last one went.

    Args:
        shortest: the shortest period [s].
        longest: the longest period [s].
        growth: the factor after a miss (>= 1).
        shrink: the factor after a period that used less than half its time.
    """

    def __init__(
        self, shortest: float, longest: float, growth: float, shrink: float
    ) -> None:
        """No miss yet: the floor is the shortest period."""
        super().__init__(shortest, longest, growth, shrink)
        self._floor = shortest
        self._floor_until = -1.0

    @property
    def floor(self) -> float:
        """The shortest period the adapter shrinks to now [s]."""
        return self._floor

    def next(self, t: float, period: float, compute: float, missed: bool) -> float:
        """The period after the one that started at ``t`` [s]."""
        if t >= self._floor_until:
            self._floor = self.shortest
        if missed:
            grown = self._grown(period)
            self._floor = max(self._floor, grown)
            self._floor_until = t + FLOOR_HOLD
            return grown
        if compute < 0.5 * period:
            return self._shrunk(period, self._floor)
        return period


class LeadAdapter(_Scaled):
    """How long before its first command a goal that arrives mid-period is planned.

    A live loop plans for such a goal within a lead and commands it at the
    lead's end (:func:`cbp.run.live.wait_out`): a
    short lead is a short latency, but a plan that takes longer than its
    lead cannot start where it was meant to and is made again. So the lead
    grows by ``growth`` after a plan made too late, and shrinks by
    ``shrink`` after one made in time, within [``shortest``, ``longest``].

    Args:
        shortest: the shortest lead [s].
        longest: the longest lead [s].
        growth: the factor after a late plan (>= 1).
        shrink: the factor after a plan in time (<= 1).
    """

    def __init__(
        self, shortest: float, longest: float, growth: float, shrink: float
    ) -> None:
        """Start at the shortest lead."""
        super().__init__(shortest, longest, growth, shrink)
        #: The lead now [s].
        self.lead = shortest

    def planned(self, in_time: bool) -> None:
        """A plan for a goal that arrived mid-period was made in time or not."""
        if in_time:
            self.lead = self._shrunk(self.lead, self.shortest)
        else:
            self.lead = self._grown(self.lead)


class DeadlineMisses:
    """Says deadline misses as events, counted rather than one by one.

    Args:
        event: records a message at a time (the run's events).
    """

    def __init__(self, event: Callable[[float, str], None]) -> None:
        """Nothing missed yet."""
        self._event = event
        self.total = 0
        self._pending = 0
        self._longest = (0.0, 0.0)  # compute, period of the longest pending
        self._said_at = -float("inf")

    def missed(self, t: float, compute: float, period: float, why: str) -> None:
        """The period that started at ``t`` missed its deadline."""
        self.total += 1
        if t - self._said_at >= MISS_REPORT and self._pending == 0:
            self._event(
                t,
                f"deadline missed ({compute * 1e3:.1f} ms for a "
                f"{period * 1e3:.1f} ms period): {why}",
            )
            self._said_at = t
            return
        self._pending += 1
        if compute / period > self._longest[0] / max(self._longest[1], 1e-12):
            self._longest = (compute, period)
        if t - self._said_at >= MISS_REPORT:
            self.flush(t)

    def met(self, t: float) -> None:
        """The period that started at ``t`` met its deadline."""
        if self._pending:
            self.flush(t, again=True)

    def flush(self, t: float, again: bool = False) -> None:
        """Say the misses counted since the last event, if any."""
        if not self._pending:
            return
        compute, period = self._longest
        self._event(
            t,
            f"deadline missed in {self._pending} more period(s) since "
            f"{self._said_at:.2f} s (the worst {compute * 1e3:.1f} ms for a "
            f"{period * 1e3:.1f} ms period)"
            + ("; deadlines met again" if again else ""),
        )
        self._pending = 0
        self._longest = (0.0, 0.0)
        self._said_at = t
