# SPDX-License-Identifier: Apache-2.0
"""A call a thread repeats that must not stop the thread when it fails."""

from __future__ import annotations

import logging
from collections.abc import Callable

__all__ = ["Guarded"]


class Guarded:
    """Runs a repeated call, and warns of a failure once until it changes.

    A page's update or a device's step runs in a thread of its own, which an
    exception must not end; the same failure at every repeat is logged once,
    and again when the error changes or after a call that succeeded.
    """

    def __init__(self, log: logging.Logger, what: str) -> None:
        """Warn to ``log`` as ``"<what> failed: <error>"``."""
        self._log = log
        self._what = what
        self._failing: str | None = None

    def call(self, step: Callable[[], object]) -> None:
        """Call ``step``; an exception it raises is logged (when new), not raised."""
        try:
            step()
        except Exception as exc:  # the caller's thread must go on
            message = f"{type(exc).__name__}: {exc}"
            if message != self._failing:
                self._log.warning("%s failed: %s", self._what, message)
            self._failing = message
        else:
            self._failing = None
