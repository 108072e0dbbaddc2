# SPDX-License-Identifier: Apache-2.0
"""Map updates off the control loop: frames in, environment snapshots out.

The control loop hands each captured frame (with the robot's configuration at
capture time) to :meth:`MapUpdater.submit`, which returns at once. A worker thread
integrates the waiting frames into the one grid (one per camera: the newest),
builds an environment snapshot and swaps it into the collision world; a frame
that arrives while the worker is busy replaces its camera's waiting one (the map
skips frames rather than lag). Queries in flight keep the snapshot they started
with.
"""

from __future__ import annotations

import threading
import time

from cbp.collision.world import CollisionWorld
from cbp.perception.camera import DepthFrame
from cbp.perception.occupancy import OccupancyGrid
from cbp.robot import FloatArray
from cbp.state import RobotState

__all__ = ["MapUpdater"]


class MapUpdater:
    """Integrates depth frames into a grid and publishes snapshots to a world.

    Args:
        grid: the occupancy grid.
        world: the collision world whose environment is replaced.
        synchronous: integrate in :meth:`submit` itself (for tests and
            deterministic replays) instead of a worker thread.

    Attributes:
        updates: snapshots published so far.
        skipped: frames replaced before the worker took them.
        last_update_s: wall time of the last integration + snapshot [s].
    """

    def __init__(
        self, grid: OccupancyGrid, world: CollisionWorld, synchronous: bool = False
    ) -> None:
        """Start the worker (unless synchronous)."""
        self.grid = grid
        self.world = world
        self.synchronous = synchronous
        self.updates = 0
        self.skipped = 0
        self.last_update_s = 0.0
        self.error: BaseException | None = None
        self._state = RobotState(world.geometry.robot)
        self._pending: dict[str, tuple[DepthFrame, FloatArray]] = {}
        self._cond = threading.Condition()
        self._stop = False
        self._busy = False
        self._thread: threading.Thread | None = None
        if not synchronous:
            self._thread = threading.Thread(
                target=self._run, name="cbp-map", daemon=True
            )
            self._thread.start()

    def submit(self, frame: DepthFrame, q: FloatArray) -> None:
        """Queue a frame taken at configuration ``q``; never waits for the map."""
        if self.synchronous:
            self._integrate([(frame, q)])
            return
        with self._cond:
            if frame.camera in self._pending:
                self.skipped += 1
            self._pending[frame.camera] = (frame, q)
            self._cond.notify()

    def wait_idle(self, timeout: float = 10.0) -> bool:
        """Block until no frame is waiting or being integrated (for tests)."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._pending or self._busy:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
        return True

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._pending and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                frames = list(self._pending.values())
                self._pending = {}
                self._busy = True
            try:
                self._integrate(frames)
            except BaseException as exc:  # reported by the executor, never lost
                self.error = exc
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()

    def _integrate(self, frames: list[tuple[DepthFrame, FloatArray]]) -> None:
        start = time.perf_counter()
        for frame, q in frames:
            self._state.update(q)
            self.grid.integrate(frame, self._state)
        self.world.set_environment(self.grid.environment())
        self.updates += 1
        self.last_update_s = time.perf_counter() - start

    def close(self) -> None:
        """Stop the worker."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
