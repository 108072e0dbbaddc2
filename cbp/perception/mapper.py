# SPDX-License-Identifier: Apache-2.0
"""Map updates off the control loop: frames in, environment snapshots out.

The control loop hands each captured frame (with the robot's configuration at
capture time) to :meth:`MapUpdater.submit`, which returns at once. A worker thread
integrates the waiting frames into the one grid (one per camera: the newest),
builds an environment snapshot and swaps it into the collision world; a frame
that arrives while the worker is busy replaces its camera's waiting one (the map
skips frames rather than lag). Queries in flight keep the snapshot they started
with. With an :class:`~cbp.perception.motion.ApproachEstimator`, each snapshot
published reports its contacts nearer by how far the obstacles approaching each
robot shape come over :attr:`MapUpdater.look_ahead`.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from cbp.collision.map_environment import OccupancyEnvironment
from cbp.collision.world import CollisionWorld
from cbp.perception.frame import DepthFrame
from cbp.perception.motion import ApproachEstimator
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
        estimator: measures how fast the map's obstacles approach the robot
            (None: snapshots as mapped).

    Attributes:
        updates: snapshots published so far.
        skipped: frames replaced before the worker took them.
        last_update_s: wall time of the last integration + snapshot [s].
        look_ahead: how far ahead approaching obstacles are measured [s] (the
            executor sets it every command period, as for declared objects).
    """

    def __init__(
        self,
        grid: OccupancyGrid,
        world: CollisionWorld,
        synchronous: bool = False,
        estimator: ApproachEstimator | None = None,
    ) -> None:
        """Start the worker (unless synchronous)."""
        self.grid = grid
        self.world = world
        self.synchronous = synchronous
        self.estimator = estimator
        self.look_ahead = 0.0
        self._mapped: OccupancyEnvironment | None = None  # the last, as mapped
        self.updates = 0
        self.skipped = 0
        self.last_update_s = 0.0
        self.error: BaseException | None = None
        self._state = RobotState(world.geometry.robot)
        self._pending: dict[str, tuple[DepthFrame, FloatArray, float]] = {}
        self._cond = threading.Condition()
        self._stop = False
        self._busy = False
        self._thread: threading.Thread | None = None
        if not synchronous:
            self._thread = threading.Thread(
                target=self._run, name="cbp-map", daemon=True
            )
            self._thread.start()

    def submit(self, frame: DepthFrame, q: FloatArray, t: float = 0.0) -> None:
        """Queue a frame taken at configuration ``q`` and time ``t`` [s].

        Never waits for the map.
        """
        if self.synchronous:
            self._integrate([(frame, q, t)])
            return
        with self._cond:
            if frame.camera in self._pending:
                self.skipped += 1
            self._pending[frame.camera] = (frame, q, t)
            self._cond.notify()

    def wait_idle(self, timeout: float = 120.0) -> bool:
        """Block until no frame is waiting or being integrated (for tests).

        ``timeout`` [s] guards against a worker that hangs; it is long enough
        for a first frame that compiles the map's loops on a loaded machine.
        False if it passed.
        """
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
                self.error = RuntimeError(f"failed, previous map kept: {exc!r}")
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()

    def _integrate(self, frames: list[tuple[DepthFrame, FloatArray, float]]) -> None:
        start = time.perf_counter()
        for frame, q, t in frames:
            self._state.update(q)
            self.grid.integrate(frame, self._state, t)
        mapped = self.grid.environment()
        published: OccupancyEnvironment = mapped
        if self.estimator is not None:
            t = max(t for _, _, t in frames)
            try:
                speeds = self.estimator.update(t, self._state, self._mapped, mapped)
                if np.any(speeds > 0):
                    published = mapped.ahead(speeds * self.look_ahead)
            except Exception as exc:  # the map itself is still published
                self.error = RuntimeError(
                    f"approach estimate failed, map published without it: {exc}"
                )
        self._mapped = mapped
        self.world.set_environment(published)
        self.updates += 1
        self.last_update_s = time.perf_counter() - start

    def close(self) -> None:
        """Stop the worker."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
