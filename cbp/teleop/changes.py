# SPDX-License-Identifier: Apache-2.0
"""A session's changes, told to whoever listens (a page that shows them at once)."""

from __future__ import annotations

import threading
from collections.abc import Callable

__all__ = ["Changes"]


class Changes:
    """Callbacks run when a session's state changes.

    A session calls :meth:`notify` from its control thread at each change a
    page shows (a command period's end, a new goal); a page listens with a
    callback that only wakes its own thread (the control loop must not wait
    for a page).
    """

    def __init__(self) -> None:
        """Nobody listens yet."""
        self._lock = threading.Lock()
        self._callbacks: tuple[Callable[[], None], ...] = ()

    def listen(self, callback: Callable[[], None]) -> None:
        """Call ``callback`` (no arguments, quick, any thread) at each change."""
        with self._lock:
            self._callbacks = (*self._callbacks, callback)

    def notify(self) -> None:
        """Tell every listener that something changed."""
        for callback in self._callbacks:
            callback()
