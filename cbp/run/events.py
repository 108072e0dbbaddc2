# SPDX-License-Identifier: Apache-2.0
"""What a run says and counts: its events, its command periods, its counters."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

from cbp.trace import PeriodRecord

__all__ = ["RunLog"]

log = logging.getLogger("cbp.run")


@dataclass
class RunLog:
    """The record a run keeps as it goes, for its trace.

    Attributes:
        method: the method that runs (each logged line names it).
        events: (time [s], message) of everything that went wrong and was
            handled, in order.
        periods: the command periods of a trajectory executor.
        counters: numbers the executor counts over the run (the trace's
            ``counters``).
    """

    method: str
    events: list[tuple[float, str]] = field(default_factory=list)
    periods: list[PeriodRecord] = field(default_factory=list)
    counters: dict[str, float] = field(default_factory=dict)

    def event(self, t: float, message: str) -> None:
        """Record (and log) something that went wrong and was handled."""
        self.events.append((t, message))
        log.info("%s t=%.3f s: %s", self.method, t, message)
