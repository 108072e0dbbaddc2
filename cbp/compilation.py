# SPDX-License-Identifier: Apache-2.0
"""Start-up compilation: counting numba's just-in-time compilations.

The collision kernels are compiled by numba the first time they are called
with a given type (or loaded from numba's cache, which is much faster). On a
fresh install the first command period of a run compiles them, which takes
about a second: a loop that times its periods asks :class:`CompileCounter`
whether a period compiled, and does not count that period as a deadline miss.
"""

from __future__ import annotations

from typing import Any

from numba.core import event

__all__ = ["CompileCounter"]


class CompileCounter(event.Listener):
    """Counts the compilations numba finishes while installed.

    Attributes:
        count: compilations finished since :meth:`install`.
    """

    def __init__(self) -> None:
        """Start at zero, not installed."""
        super().__init__()
        self.count = 0

    def on_start(self, event: Any) -> None:
        """Nothing: a compilation counts when it ends."""

    def on_end(self, event: Any) -> None:
        """One more compilation."""
        self.count += 1

    @classmethod
    def install(cls) -> CompileCounter:
        """A counter that hears every compilation from now on."""
        counter = cls()
        event.register("numba:compile", counter)  # type: ignore[no-untyped-call]
        return counter

    def uninstall(self) -> None:
        """Stop counting."""
        event.unregister("numba:compile", self)  # type: ignore[no-untyped-call]
