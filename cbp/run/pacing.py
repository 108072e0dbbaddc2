# SPDX-License-Identifier: Apache-2.0
"""One wall-clock pacer for every live loop: simulated time kept in step with now.

A live session runs its simulation no faster than the wall clock, so the
operator sees the arm move in real time: after each step to simulated time
``t`` the loop waits until ``t`` seconds have passed since it started. A loop
that falls behind catches up (it does not wait) unless ``max_lag`` says how
far behind it may fall before the lost time is given up (a page's redraws,
which need not be made up).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

__all__ = ["LoopClock", "Pacer", "WallClockPacer"]


class Pacer(Protocol):
    """What a live loop asks of its clock: wait for a time, say how long is left.

    :class:`WallClockPacer` is the wall clock's; a test may pace a loop on a
    clock of its own (the same loop, on virtual time).
    """

    def wait_until(self, t: float, wakeable: bool = True) -> float:
        """Wait until the loop's time ``t`` is now (or a wake); return how late [s]."""
        ...

    def left(self, t: float) -> float:
        """How long until the loop's time ``t`` is now [s] (< 0: past)."""
        ...


class WallClockPacer:
    """Waits until the wall clock reaches a loop's simulated time.

    Args:
        max_lag: the longest the loop may be behind before the pacer gives up
            the lost time [s] (inf: always catch up).
        wake: an event that ends any wait at once (a stop request; a live
            session's new goal).

    The wall-clock origin is taken at the first :meth:`wait_until` (or
    :meth:`start`): the loop's time then is now.
    """

    def __init__(
        self, max_lag: float = math.inf, wake: threading.Event | None = None
    ) -> None:
        """Not started yet."""
        if not max_lag > 0:
            raise ValueError(f"max_lag must be > 0, got {max_lag}")
        self.max_lag = max_lag
        self.wake = wake
        self._origin: float | None = None

    def start(self, t: float = 0.0) -> None:
        """Take the wall clock's origin now, where the loop's time is ``t``."""
        self._origin = time.perf_counter() - t

    @property
    def started(self) -> bool:
        """Whether the origin is taken."""
        return self._origin is not None

    def wall_time(self, t: float) -> float:
        """The ``time.perf_counter()`` reading at which the loop's time is ``t``."""
        if self._origin is None:
            self.start(t)
        assert self._origin is not None
        return self._origin + t

    def wait_until(self, t: float, wakeable: bool = True) -> float:
        """Wait until the loop's time ``t`` is now; return how late it was [s].

        Returns at once when the loop is behind (the lateness, > 0) or, when
        ``wakeable``, when ``wake`` is set (:meth:`left` then says how early).
        """
        due = self.wall_time(t)
        now = time.perf_counter()
        late = now - due
        if late > self.max_lag:
            assert self._origin is not None
            self._origin += late - self.max_lag
        if late >= 0:
            return late
        if self.wake is not None and wakeable:
            self.wake.wait(-late)
        else:
            time.sleep(-late)
        return 0.0

    def left(self, t: float) -> float:
        """How long until the loop's time ``t`` is now [s] (< 0: past)."""
        return self.wall_time(t) - time.perf_counter()


def _never() -> bool:
    return False


@dataclass(frozen=True)
class LoopClock:
    """How a run's loop keeps time: its one strategy for pacing.

    Attributes:
        live: waits out each period on this pacer, planning for each goal that
            arrives meanwhile at once (a live session); None: the loop runs
            as fast as the work allows.
        world: keeps the simulated world from running ahead of the wall
            clock (a run with cameras on the wall clock, whose map works
            beside the loop in real time); None: no such limit.
        stop: asked at each period's start; True ends the run there (an
            operator's stop).
    """

    live: Pacer | None = None
    world: WallClockPacer | None = None
    stop: Callable[[], bool] = field(default=_never)

    @classmethod
    def unpaced(cls, world_in_step: bool = False) -> LoopClock:
        """As fast as the work allows (``world_in_step``: not ahead of the wall)."""
        return cls(world=WallClockPacer() if world_in_step else None)

    @classmethod
    def paced(cls, pacer: Pacer, stop: Callable[[], bool] = _never) -> LoopClock:
        """A live loop on ``pacer``, stopped when ``stop()`` says so."""
        return cls(live=pacer, stop=stop)

    def planning_time(self, budget: float, t: float) -> float:
        """A period's planning budget [s]: ``budget``, less how late it starts.

        On the wall clock the simulated world and the cameras take their
        share of the same core after the plan; a period that starts behind
        the wall clock plans that much less, down to :data:`MIN_BUDGET_SHARE`
        of ``budget``, so the world catches up instead of falling further
        behind. Measured on the generated scene moving_11 with the cameras
        (the map in its own process, load 1): planning took up to 85 % of
        each period and simulating the world and rendering its cameras 35 %,
        so the world fell 0.4 s behind the wall clock in 3 s and caught up
        in a burst once the plans came quickly.
        """
        pacer = self.live or self.world
        if pacer is None:
            return budget
        late = -pacer.left(t)
        if late <= 0.0:
            return budget
        return max(MIN_BUDGET_SHARE * budget, budget - late)


#: The least share of its planning budget a period keeps when the simulated
#: world is behind the wall clock (:meth:`LoopClock.planning_time`).
MIN_BUDGET_SHARE = 0.25
