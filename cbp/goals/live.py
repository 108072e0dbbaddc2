# SPDX-License-Identifier: Apache-2.0
"""The operator's live goal: set from any thread, sampled by the control loop.

A goal source of its own kind (not a scenario's ``goal:`` section): the
teleoperation page and the devices set it, and a run's parts take it
(:func:`cbp.run.build_run`'s ``goal``).
"""

from __future__ import annotations

import threading
import time

import numpy as np

from cbp.robot import FloatArray

__all__ = ["LiveGoal"]


class LiveGoal:
    """The operator's goal: set from any thread, sampled by the control loop.

    Nothing is checked here: the run checks every sample as it does a
    scenario's stream (a malformed goal is rejected and the previous one kept,
    said once per episode with a count).

    Args:
        position: the starting goal position (3,) [m].
        rotation: the starting goal rotation (3, 3).
        rate_hz: the rate at which the control loop samples it [Hz].
    """

    def __init__(
        self, position: FloatArray, rotation: FloatArray, rate_hz: float = 30.0
    ) -> None:
        """Start at the given pose."""
        self._lock = threading.Lock()
        self._position = np.array(position, dtype=float)
        self._rotation = np.array(rotation, dtype=float)
        self._rate_hz = float(rate_hz)
        #: Number of goals set so far (the starting one is 0).
        self.count = 0
        self._arrival: dict[int, float] = {0: time.perf_counter()}
        #: When the control loop first sampled each goal (``time.perf_counter()``).
        self._taken: dict[int, float] = {}
        self._sampled = 0
        #: Set when a goal is set, cleared when the control loop samples it:
        #: a live loop's pacer waits on it, so a new goal ends its wait.
        self.arrived = threading.Event()

    @property
    def rate_hz(self) -> float:
        """Rate at which the control loop samples the goal [Hz]."""
        return self._rate_hz

    def set(self, position: FloatArray, rotation: FloatArray) -> int:
        """Make (position, rotation) the goal; return its number."""
        with self._lock:
            self._position = np.array(position, dtype=float).reshape(3)
            self._rotation = np.array(rotation, dtype=float).reshape(3, 3)
            self.count += 1
            self._arrival[self.count] = time.perf_counter()
            self.arrived.set()
            return self.count

    def pose(self) -> tuple[FloatArray, FloatArray]:
        """The latest goal (copies)."""
        with self._lock:
            return self._position.copy(), self._rotation.copy()

    def sample(self, t: float) -> tuple[FloatArray, FloatArray]:
        """The latest goal; the control loop's sample at ``t`` [s]."""
        with self._lock:
            self._sampled = self.count
            self.arrived.clear()
            self._taken.setdefault(self.count, time.perf_counter())
            return self._position.copy(), self._rotation.copy()

    @property
    def sampled_number(self) -> int:
        """The number of the goal the control loop sampled last."""
        return self._sampled

    def changed(self) -> bool:
        """Whether a goal was set after the last sample."""
        return self.count != self._sampled

    def take_sampled(self) -> tuple[int, float, float] | None:
        """The latest sampled goal's number, arrival and first sample, once each.

        Times are ``time.perf_counter()`` [s].
        """
        with self._lock:
            n = self._sampled
            arrival = self._arrival.pop(n, None)
            taken = self._taken.pop(n, None)
            # Goals superseded before they were sampled have no latency.
            for old in [k for k in self._arrival if k < n]:
                del self._arrival[old]
            for old in [k for k in self._taken if k < n]:
                del self._taken[old]
        if arrival is None or taken is None:
            return None
        return n, arrival, taken
