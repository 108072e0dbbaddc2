# SPDX-License-Identifier: Apache-2.0
"""Unexpected exceptions in a run's loop: recorded, survived, and bounded.

Every executor's loop calls parts that can fail in ways the loop does not
expect: a plugin, the solver, the collision world, a camera, the goal stream,
the simulator. Such an exception must not end the run with nothing written.
:class:`Faults` turns it into an event while the executor holds the robot on a
trajectory it can follow; after :data:`MAX_FAULTS_IN_A_ROW` failures in a row
(without one good control cycle between them) the run is aborted: the robot is
stopped, the run ends early, and the trace, metrics and report say why
(``aborted`` in ``metrics.json``; ``cbp run`` exits with :data:`EXIT_ABORTED`).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

__all__ = [
    "EXIT_ABORTED",
    "EXIT_INCOMPLETE",
    "MAX_FAULTS_IN_A_ROW",
    "STOPPED_EARLY",
    "Faults",
    "clear_stop",
    "describe",
    "request_stop",
]

log = logging.getLogger(__name__)

#: Control cycles in a row that may fail before the run is aborted.
MAX_FAULTS_IN_A_ROW = 10
#: Exit status of ``cbp run`` and ``cbp compare`` when a run was aborted (its
#: outputs are written).
EXIT_ABORTED = 3
#: Exit status of ``cbp run`` and ``cbp compare`` when a stage after the control
#: loop failed (the ground-truth clearance, metrics, plots, the report): the
#: outputs are written without it, and an event and ``incomplete`` in
#: ``metrics.json`` name it.
EXIT_INCOMPLETE = 4


#: How the reason of a run stopped on request begins (``aborted``).
STOPPED_EARLY = "stopped early"
#: A stop asked of every run in this process (``cbp run`` on SIGINT, SIGTERM
#: or SIGHUP), and why.
_STOP = threading.Event()
_STOP_REASON = [""]


def request_stop(reason: str) -> None:
    """Ask every run of this process to stop at its next control cycle.

    The run ends as an aborted one does: the robot brakes to rest, and the
    trace, metrics and report are written up to there, ``aborted`` saying
    ``reason``. Safe to call from a signal handler.
    """
    _STOP_REASON[0] = reason
    _STOP.set()


def clear_stop() -> None:
    """Forget a stop asked before (a new run may start)."""
    _STOP.clear()
    _STOP_REASON[0] = ""


class Faults:
    """Counts a loop's unexpected exceptions and decides when to give up.

    Args:
        event: records a message at a time (the run's events).
        limit: failures in a row that abort the run.

    Attributes:
        total: failures so far.
        in_a_row: failures since the last good cycle.
        aborted: why the run was aborted, or None.
    """

    def __init__(
        self, event: Callable[[float, str], None], limit: int = MAX_FAULTS_IN_A_ROW
    ) -> None:
        """No failures yet."""
        self._event = event
        self.limit = limit
        self.total = 0
        self.in_a_row = 0
        self._aborted: str | None = None

    @property
    def aborted(self) -> str | None:
        """Why the run was aborted (or asked to stop: :func:`request_stop`), or None."""
        if self._aborted is None and _STOP.is_set():
            self._aborted = f"{STOPPED_EARLY}: {_STOP_REASON[0]}"
        return self._aborted

    def fault(self, t: float, where: str, exc: BaseException) -> str:
        """Record that ``where`` raised ``exc`` at ``t``; return the message.

        The run is aborted when this is the ``limit``-th failure in a row.
        """
        self.total += 1
        self.in_a_row += 1
        what = describe(exc)
        message = f"{where} failed ({what}); robot held"
        log.debug("%s at t=%.3f s", where, t, exc_info=exc)
        self._event(t, message)
        if self.in_a_row >= self.limit and self.aborted is None:
            self._aborted = f"{where} failed {self.in_a_row} times in a row ({what})"
            self._event(t, f"run aborted: {self._aborted}")
        return message

    def ok(self) -> None:
        """A control cycle went through: the count in a row starts again."""
        self.in_a_row = 0


def describe(exc: BaseException) -> str:
    """An exception as an event names it: ``InjectedError: what happened``."""
    return f"{type(exc).__name__}: {exc}".strip().rstrip(":")
