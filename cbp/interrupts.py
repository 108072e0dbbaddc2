# SPDX-License-Identifier: Apache-2.0
"""Stop signals noted, not obeyed at once, so that what ran is always written.

A SIGINT (Ctrl-C), SIGTERM or SIGHUP that arrives while a run's outputs are
written must not lose the run. A :class:`SignalGuard` installed over the
writing notes each one; only inside :meth:`SignalGuard.interruptible` (the
figures and the report, drawn after the trace and metrics are on disk) does
one raise :class:`Interrupted`, which the writer answers by leaving the rest
out. ``cbp run`` installs one guard over the run and its outputs: the first
signal stops the run (its outputs are all written), any later one cuts the
figures short.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType, TracebackType
from typing import Any

__all__ = ["STOP_SIGNALS", "Interrupted", "SignalGuard"]

#: The signals that stop a command, by how events and messages name them.
STOP_SIGNALS: dict[int, str] = {
    signal.SIGINT: "SIGINT (Ctrl-C)",
    signal.SIGTERM: "SIGTERM",
    signal.SIGHUP: "SIGHUP",
}


class Interrupted(BaseException):
    """A stop signal arrived where a guard lets one interrupt.

    A BaseException, as KeyboardInterrupt is: stages that survive their own
    failures (``except Exception``) do not swallow it.

    Attributes:
        name: the signal's name (:data:`STOP_SIGNALS`).
    """

    def __init__(self, name: str) -> None:
        """Interrupted by the signal named ``name``."""
        super().__init__(name)
        self.name = name


class SignalGuard:
    """While installed (``with``), the stop signals are noted, not obeyed.

    Only the main thread can install signal handlers: elsewhere the guard
    installs nothing and notes nothing.

    Args:
        on_signal: called with each signal's name as it arrives (in the
            handler: keep it short and safe, e.g.
            :func:`cbp.run.faults.request_stop`).

    Attributes:
        received: the names of the signals received so far, in order.
        answered: how many of them were answered otherwise (a run stopped):
            only the ones after interrupt :meth:`interruptible`.
    """

    def __init__(self, on_signal: Callable[[str], None] | None = None) -> None:
        """Nothing installed, nothing received yet."""
        self.on_signal = on_signal
        self.received: list[str] = []
        self.answered = 0
        self._numbers: list[int] = []
        self._raising = False
        self._before: dict[int, Any] = {}

    @property
    def unanswered(self) -> list[str]:
        """The signals received beyond the :attr:`answered` ones."""
        return self.received[self.answered :]

    def __enter__(self) -> SignalGuard:
        """Install the handler (main thread only)."""
        if threading.current_thread() is threading.main_thread():
            self._before = {s: signal.signal(s, self._handle) for s in STOP_SIGNALS}
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        """Put the handlers that were there before back."""
        for number, handler in self._before.items():
            signal.signal(number, handler)
        self._before = {}

    def _handle(self, number: int, frame: FrameType | None) -> None:
        name = STOP_SIGNALS[number]
        self.received.append(name)
        self._numbers.append(number)
        if self.on_signal is not None:
            self.on_signal(name)
        if self._raising:
            self._raising = False  # a signal during the answer is only noted
            raise Interrupted(name)

    @contextlib.contextmanager
    def interruptible(self) -> Iterator[None]:
        """While inside, an unanswered signal raises :class:`Interrupted`.

        One already received raises it at once, on entering.
        """
        if self.unanswered:
            raise Interrupted(self.unanswered[0])
        self._raising = bool(self._before)
        try:
            yield
        finally:
            self._raising = False

    def deliver(self) -> None:
        """Act on each signal noted as the handlers now installed would have.

        Called once the guard is removed, by a writer that installed it for
        its own work: a process that dies on SIGTERM still does, after the
        outputs are safe; Ctrl-C still raises KeyboardInterrupt.
        """
        numbers, self._numbers = self._numbers, []
        for number in numbers:
            signal.raise_signal(number)
