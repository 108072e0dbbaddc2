# SPDX-License-Identifier: Apache-2.0
"""What a run says and counts: its events, its command periods, its counters.

A run's log is what its loop tells the world: the events, how far the run
has come, when a trajectory was commanded and up to when the robot's motion
is simulated. Whoever shows or writes it (a command's progress bar, a live
page) is a :class:`RunListener`; listeners are given to the runs started
inside :func:`listening`, so the library never formats a report itself.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field

from cbp.trace import PeriodRecord

__all__ = ["EPISODE_GAP", "Repeating", "RunListener", "RunLog", "listening"]

log = logging.getLogger("cbp.run")


class RunListener:
    """Told what a run does as it goes; override what you want to hear.

    Every method is called on the run's own thread and should return quickly.
    """

    def event(self, t: float, message: str) -> None:
        """Something went wrong at ``t`` [s] and was handled (``message``)."""

    def progress(self, t: float, duration: float) -> None:
        """The run has reached ``t`` of its ``duration`` [s] (simulated time)."""

    def commanded(self, t: float) -> None:
        """A trajectory starting at ``t`` [s] was spliced into the robot's command."""

    def reached(self, t: float) -> None:
        """The robot's motion is simulated up to ``t`` [s] (its state is new)."""


_LISTENERS: ContextVar[tuple[RunListener, ...]] = ContextVar(
    "cbp_run_listeners", default=()
)


@contextmanager
def listening(*listeners: RunListener) -> Iterator[None]:
    """Give ``listeners`` (and those already listening) to the runs started inside."""
    token = _LISTENERS.set(_LISTENERS.get() + listeners)
    try:
        yield
    finally:
        _LISTENERS.reset(token)


def _current_listeners() -> list[RunListener]:
    return list(_LISTENERS.get())


@dataclass
class RunLog:
    """The record a run keeps as it goes, for its trace, told to its listeners.

    Attributes:
        method: the method that runs (each logged line names it).
        duration: the run's length [s] (for :meth:`progress`).
        events: (time [s], message) of everything that went wrong and was
            handled, in order.
        periods: the command periods of a trajectory executor.
        counters: numbers the executor counts over the run (the trace's
            ``counters``).
        listeners: told of events, progress and commands (those of the
            :func:`listening` context the log was made in, and any added).
    """

    method: str
    duration: float = 0.0
    events: list[tuple[float, str]] = field(default_factory=list)
    periods: list[PeriodRecord] = field(default_factory=list)
    counters: dict[str, float] = field(default_factory=dict)
    listeners: list[RunListener] = field(default_factory=_current_listeners)

    def event(self, t: float, message: str) -> None:
        """Record (and log) something that went wrong and was handled."""
        self.events.append((t, message))
        log.info("%s t=%.3f s: %s", self.method, t, message)
        for listener in self.listeners:
            listener.event(t, message)

    def progress(self, t: float) -> None:
        """The run has reached simulated time ``t`` [s]."""
        for listener in self.listeners:
            listener.progress(t, self.duration)

    def commanded(self, t: float) -> None:
        """A trajectory starting at ``t`` [s] was commanded."""
        for listener in self.listeners:
            listener.commanded(t)

    def reached(self, t: float) -> None:
        """The robot's motion is simulated up to ``t`` [s]."""
        for listener in self.listeners:
            listener.reached(t)


#: Occurrences of a repeating event closer than this [s] are one episode.
EPISODE_GAP = 1.0


class Repeating:
    """An event that repeats, said once per episode with a count.

    The first occurrence of an episode is said at once, with its detail;
    later ones less than :data:`EPISODE_GAP` after the one before are
    counted, and said as one line when the episode ends (the next
    occurrence after a quiet gap, or :meth:`flush` at the run's end).

    Args:
        event: records a message at a time (the run's events).
        what: what happens ("QP eased").
    """

    def __init__(self, event: Callable[[float, str], None], what: str) -> None:
        """No episode yet."""
        self._event, self.what = event, what
        self.total = 0
        self._since: float | None = None
        self._last = 0.0
        self._more = 0

    def happened(self, t: float, detail: str) -> None:
        """It happened at ``t`` [s]; ``detail`` says how."""
        self.total += 1
        if self._since is not None and t - self._last < EPISODE_GAP:
            self._more += 1
            self._last = t
            return
        self.flush()
        self._event(t, f"{self.what}: {detail}")
        self._since = self._last = t

    def flush(self) -> None:
        """Say how often the episode under way repeated, if it did; end it."""
        if self._since is not None and self._more:
            self._event(
                self._last,
                f"{self.what} {self._more} more time(s) from {self._since:.2f} "
                f"to {self._last:.2f} s",
            )
        self._since, self._more = None, 0
