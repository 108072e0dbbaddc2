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

Each snapshot is stamped with the capture time of its newest frame
(:attr:`~cbp.collision.map_environment.OccupancyEnvironment.stamp`), and the
updater keeps a record of each publication (:class:`Publication`). A thread
shares the interpreter lock with the control loop;
:class:`~cbp.perception.map_process.ProcessMapUpdater` has the same interface
and runs the map in a process of its own.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from cbp.collision.map_environment import OccupancyEnvironment
from cbp.collision.world import CollisionWorld
from cbp.perception.frame import DepthFrame
from cbp.perception.motion import ApproachEstimator, ClusterMotion, swept_snapshot
from cbp.perception.moving import frame_period, moving_growth, with_moving
from cbp.perception.occupancy import OccupancyGrid
from cbp.robot import FloatArray
from cbp.state import RobotState

__all__ = [
    "MapUpdater",
    "Publication",
    "SnapshotPublisher",
    "cluster_motion",
    "integrate_frames",
]

#: Publications kept in :attr:`SnapshotPublisher.published`.
KEPT_PUBLICATIONS = 4096


@dataclass(frozen=True)
class Publication:
    """One snapshot made public to the collision world.

    Attributes:
        stamp: capture time of the newest frame in it [s of the run's clock].
        frames: frames it took in.
        received: when the updater took the frames (``time.perf_counter``,
            the same clock in every process of the machine) [s].
        integrate_s: wall time integrating them [s].
        snapshot_s: wall time building the snapshot (and the approach
            estimate) [s].
        published: when the collision world had it (``time.perf_counter``) [s].
    """

    stamp: float
    frames: int
    received: float
    integrate_s: float
    snapshot_s: float
    published: float


def cluster_motion(grid: OccupancyGrid) -> ClusterMotion | None:
    """The grid's cluster-motion estimate, or None (``perception.cluster_motion``)."""
    spec = grid.spec
    if not spec.cluster_motion or spec.motion_window <= 0:
        return None
    return ClusterMotion(grid.lower, grid.cell, spec.motion_window)


def integrate_frames(
    grid: OccupancyGrid,
    state: RobotState,
    frames: list[tuple[DepthFrame, FloatArray, float]],
) -> None:
    """Integrate ``frames`` (frame, configuration, capture time) in time order.

    The frames of one capture time together
    (:meth:`~cbp.perception.occupancy.OccupancyGrid.integrate_together`): a
    cell one camera sees through at an instant is free, whatever another
    camera's reading of that instant hides. ``state`` is updated to each
    frame's configuration in turn (the last one's after).
    """
    ordered = sorted(frames, key=lambda f: f[2])
    k = 0
    while k < len(ordered):
        t = ordered[k][2]
        group: list[tuple[DepthFrame, RobotState | None, float | None]] = []
        while k < len(ordered) and ordered[k][2] == t:
            frame, q, _ = ordered[k]
            group.append((frame, RobotState(state.robot, q), t))
            k += 1
        grid.integrate_together(group)
        state.update(ordered[k - 1][1])


class SnapshotPublisher:
    """What every map updater tells its executor, however it runs.

    Attributes:
        updates: snapshots published so far.
        skipped: frames replaced before the map took them.
        last_update_s: wall time of the last integration + snapshot [s].
        look_ahead: how far ahead approaching obstacles are measured [s] (the
            executor sets it every command period, as for declared objects).
        error: a failure to report as an event (the executor clears it).
        failed: why the map stopped for good (its process died), or None.
        published: the last :data:`KEPT_PUBLICATIONS` publications.
    """

    def __init__(self) -> None:
        """Nothing published yet."""
        self.look_ahead = 0.0
        self.updates = 0
        self.skipped = 0
        self.last_update_s = 0.0
        self.error: BaseException | None = None
        self.failed: str | None = None
        self.published: deque[Publication] = deque(maxlen=KEPT_PUBLICATIONS)
        #: Capture time of the newest frame submitted, and of the newest one
        #: published [s of the run's clock].
        self.submitted_t = 0.0
        self.stamp = 0.0

    def release(self, t: float) -> None:
        """Install the snapshots due by ``t`` [s] (a virtual map's latency).

        Nothing to do where the map publishes as soon as it is done.
        """

    def hold_reason(self, timeout: float) -> str | None:
        """Why the robot must hold, or None: the map failed, or lags.

        The map lags when the newest frame submitted is more than ``timeout``
        [s] newer than the newest one published (the map no longer keeps up
        with the cameras: as stale as a camera that gives no frames).
        """
        if self.failed is not None:
            return f"map failed ({self.failed}): robot stopped"
        if self.submitted_t - self.stamp > timeout:
            return (
                f"the map is more than {timeout:g} s behind the cameras: robot stopped"
            )
        return None


class MapUpdater(SnapshotPublisher):
    """Integrates depth frames into a grid and publishes snapshots to a world.

    Args:
        grid: the occupancy grid.
        world: the collision world whose environment is replaced.
        synchronous: integrate in :meth:`submit` itself (for tests and
            deterministic replays) instead of a worker thread.
        latency: with ``synchronous``, each snapshot is installed this long
            after the capture of its newest frame [s of the run's clock], at
            the first :meth:`release` from then on, and measured ahead over
            that age as a map process's snapshots are
            (``perception.virtual_latency``); 0: at once.
        estimator: measures how fast the map's obstacles approach the robot
            (None: snapshots as mapped; with it and
            ``perception.cluster_motion``, moving clusters are swept too).
        batch: with ``synchronous``, the frames of one capture time make one
            snapshot: each frame is integrated at once, the snapshot is made
            when a frame of a later time comes or at :meth:`release` (the
            cameras of a run capture at the same instants; the loop plans
            only after all of them, so the snapshots between were never
            seen). As the worker does on the wall clock, which takes the
            frames waiting together.

    What it reports (updates, skips, stamps, failures): :class:`SnapshotPublisher`.
    """

    def __init__(
        self,
        grid: OccupancyGrid,
        world: CollisionWorld,
        synchronous: bool = False,
        estimator: ApproachEstimator | None = None,
        latency: float = 0.0,
        batch: bool = False,
    ) -> None:
        """Start the worker (unless synchronous)."""
        super().__init__()
        self.batch = batch and synchronous
        #: Frames of one instant, not yet integrated (``batch``).
        self._held: list[tuple[DepthFrame, FloatArray, float]] = []
        self.grid = grid
        self.world = world
        self.synchronous = synchronous
        self.latency = float(latency) if synchronous else 0.0
        #: Snapshots made, waiting for their time: (due [s], stamp [s],
        #: snapshot). The stamp is kept apart: a map that has not changed
        #: gives its last snapshot again, maybe still waiting here.
        self._due: deque[tuple[float, float, OccupancyEnvironment]] = deque()
        self.estimator = estimator
        self._mapped: OccupancyEnvironment | None = None  # the last, as mapped
        #: Velocities of the mapped obstacles, cluster by cluster (with an
        #: estimator, when ``perception.cluster_motion`` is on).
        self.clusters = cluster_motion(grid) if estimator is not None else None
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
        self.submitted_t = max(self.submitted_t, t)
        if self.batch:
            if self._held and t > self._held[-1][2]:
                self._publish_held()
            self._held.append((frame, q, t))
            return
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
        integrate_frames(self.grid, self._state, frames)
        self._publish(frames, start, time.perf_counter())

    def _publish_held(self) -> None:
        """Integrate the frames held, of one instant, and snapshot (``batch``)."""
        frames, self._held = self._held, []
        self._integrate(frames)

    def _publish(
        self,
        frames: list[tuple[DepthFrame, FloatArray, float]],
        start: float,
        integrated: float,
    ) -> None:
        """Snapshot the grid after ``frames`` and publish it.

        ``start`` to ``integrated`` (``time.perf_counter``): when they were
        integrated; the robot as in the last of them.
        """
        mapped = self.grid.environment()
        stamp = max(t for _, _, t in frames)
        mapped.stamp = stamp
        published: OccupancyEnvironment = mapped
        if self.clusters is not None and self.grid.geometry is not None:
            try:
                shapes = self.grid.geometry.world_shapes(self._state)
                moving = self.clusters.update(stamp, self.grid.cells, shapes)
                published = swept_snapshot(
                    mapped, moving, self.look_ahead + self.latency, self.grid.lower
                )
            except Exception as exc:  # the map itself is still published
                self.error = RuntimeError(
                    f"cluster motion failed, map published without it: {exc}"
                )
        if self.estimator is not None:
            t = stamp
            try:
                speeds = self.estimator.update(t, self._state, self._mapped, mapped)
                if np.any(speeds > 0):
                    published = published.ahead(
                        speeds * (self.look_ahead + self.latency)
                    )
            except Exception as exc:  # the map itself is still published
                self.error = RuntimeError(
                    f"approach estimate failed, map published without it: {exc}"
                )
        self._mapped = mapped
        grid = self.grid
        entered, newest = grid.moving(stamp)
        published = with_moving(
            published,
            entered,
            moving_growth(
                grid.spec.moving_speed,
                self.look_ahead,
                self.latency,
                stamp - newest,
                grid.cell,
                frame_period(grid.spec),
            ),
            grid.cells,
            grid.lower,
        )
        published.stamp = stamp
        if self.latency > 0.0:
            self._due.append((stamp + self.latency, stamp, published))
            self.release(self.submitted_t)
        else:
            self._install(published, stamp)
        done = time.perf_counter()
        self.last_update_s = done - start
        self.published.append(
            Publication(
                stamp, len(frames), start, integrated - start, done - integrated, done
            )
        )

    def release(self, t: float) -> None:
        """Install the newest snapshot due by ``t`` [s] (see ``latency``).

        With ``batch``, the frames held are snapshot first.
        """
        if self._held:
            self._publish_held()
        newest = None
        while self._due and self._due[0][0] <= t + 1e-9:
            _, stamp, snapshot = self._due.popleft()
            newest = (snapshot, stamp)
        if newest is not None:
            self._install(*newest)

    def _install(self, published: OccupancyEnvironment, stamp: float) -> None:
        """Hand ``published``, stamped ``stamp`` [s], to the world."""
        published.stamp = stamp
        self.world.set_environment(published)
        self.stamp = max(self.stamp, stamp)
        self.updates += 1

    def close(self) -> None:
        """Stop the worker."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
