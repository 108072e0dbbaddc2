# SPDX-License-Identifier: Apache-2.0
"""Progress of long commands: a rich bar on a terminal, plain lines elsewhere.

``cbp sweep`` and ``cbp compare`` report each finished run, and ``cbp run``
the simulated time of its run (:func:`run_progress`, a listener on the run's
log). Attached to a
terminal (and with ``rich``, from the sweep extra, installed) a bar shows runs
done, failures and the time left; otherwise, when asked, one line per finished
run goes to standard error, which logs and CI keep readably.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from cbp.run.events import RunListener, listening

__all__ = ["Progress", "run_progress"]


class Progress:
    """Counts finished items of a long command and shows them.

    Args:
        total: items to do.
        label: what is counted ("sweep", "compare").
        done: items already done (a resumed sweep).
        lines: print a plain line per item when there is no bar.
    """

    def __init__(self, total: int, label: str, done: int = 0, lines: bool = False):
        """Nothing is shown until the context is entered."""
        self.total, self.done, self.label = total, done, label
        self.lines = lines
        self.failed = 0
        self._bar: Any = None
        self._start = time.monotonic()

    def __enter__(self) -> Progress:
        """Start the bar on a terminal with rich installed."""
        if not sys.stderr.isatty():
            return self
        try:
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                TextColumn,
                TimeRemainingColumn,
            )
            from rich.progress import Progress as Bar
        except ImportError:  # no rich: plain lines
            return self
        self._bar = Bar(
            TextColumn(self.label),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("[red]{task.fields[failed]} failed"),
            TextColumn("{task.fields[item]}"),
            TimeRemainingColumn(),
        )
        self._bar.start()
        self._task = self._bar.add_task(
            self.label, total=self.total, completed=self.done, failed=0, item=""
        )
        return self

    def advance(self, item: str = "", failed: bool = False) -> None:
        """One more item done (``item`` names it)."""
        self.done += 1
        self.failed += failed
        if self._bar is not None:
            self._bar.update(self._task, advance=1, failed=self.failed, item=item)
        elif self.lines:
            elapsed = time.monotonic() - self._start
            state = " (failed)" if failed else ""
            print(
                f"{self.label}: {self.done}/{self.total} {item}{state}, "
                f"{elapsed:.0f} s",
                file=sys.stderr,
                flush=True,
            )

    def __exit__(self, *exc: object) -> None:
        """Stop the bar."""
        if self._bar is not None:
            self._bar.stop()


class _RunBar(RunListener):
    """A run's simulated time: a bar on a terminal, else a line every tenth."""

    def __init__(self, label: str) -> None:
        self.label = label
        self.bar: Any = None
        self.task: Any = None
        self.next = 0.1
        if sys.stderr.isatty():
            try:
                from rich.progress import BarColumn, TextColumn, TimeRemainingColumn
                from rich.progress import Progress as Bar
            except ImportError:
                return
            self.bar = Bar(
                TextColumn(label),
                BarColumn(),
                TextColumn("{task.completed:.1f}/{task.total:.1f} s"),
                TimeRemainingColumn(),
            )
            self.bar.start()
            self.task = self.bar.add_task(label, total=1.0)

    def progress(self, t: float, duration: float) -> None:
        if self.bar is not None:
            self.bar.update(self.task, completed=t, total=duration)
        elif duration > 0 and t / duration >= self.next - 1e-9:
            print(
                f"{self.label}: {t:.1f} of {duration:.1f} s",
                file=sys.stderr,
                flush=True,
            )
            while self.next <= t / duration + 1e-9:
                self.next += 0.1

    def stop(self) -> None:
        if self.bar is not None:
            self.bar.stop()


@contextmanager
def run_progress(label: str) -> Iterator[None]:
    """Show the progress of the runs inside.

    A bar of simulated time on a terminal, a line every tenth of the run
    otherwise (on standard error): a listener on the runs' logs.
    """
    bar = _RunBar(label)
    try:
        with listening(bar):
            yield
    finally:
        bar.stop()
