# SPDX-License-Identifier: Apache-2.0
"""The map in a process of its own: frames in, stamped snapshots out.

A :class:`~cbp.perception.mapper.MapUpdater` thread shares the interpreter lock
with the control loop: each of its Python steps waits for the loop to let go of
it, and the loop waits for the map's. :class:`ProcessMapUpdater` has the same
interface and integrates the frames in a child process (started with
``forkserver`` where the platform has it, else ``spawn``: never ``fork``, which
would copy the simulator's state and threads), so the two run on two cores.

* Frames go to the child through shared memory, one slot per camera:
  :meth:`ProcessMapUpdater.submit` copies the depth image, the camera's
  matrices, the robot's configuration and the capture time into the camera's
  slot (a sequence number around the copy tells the child a frame that was
  being overwritten) and wakes the child; it never waits. A frame not yet
  taken is overwritten by its camera's next one: the map skips frames rather
  than lag, and no backlog builds up anywhere (a queue's backlog would wait
  in the control process for the interpreter lock).
* The grid's cells live in shared memory (:mod:`multiprocessing.shared_memory`):
  the child writes them, the control process reads them
  (:meth:`~cbp.perception.occupancy.OccupancyGrid.state_at` for unseen space,
  the teleoperation page's drawing).
* Each snapshot (the obstacle shell by brick, and the dense obstacle mask) is
  written to one of :data:`SLOTS` shared-memory slots; a short message over a
  pipe says which, with the capture time of its newest frame (its stamp), the
  approach speeds and the timings. A receiver thread in the control process
  copies the slot out, hands the slot back, and swaps the snapshot into the
  collision world. The child writes only into slots handed back.
* The approach estimate (:class:`~cbp.perception.motion.ApproachEstimator`)
  and the clusters' motion (:class:`~cbp.perception.motion.ClusterMotion`)
  run in the child. The control process measures each snapshot's contacts
  nearer by the approach, and sweeps the moving clusters, over the look-ahead
  *plus the snapshot's age* (the newest capture time submitted less its
  stamp): planned against where the obstacles will be, not where they were.

The control process creates every shared-memory segment and unlinks them all in
:meth:`ProcessMapUpdater.close`, whatever became of the child. A child that
dies is reported once (:attr:`~cbp.perception.mapper.SnapshotPublisher.error`,
an event) and holds the robot for good
(:meth:`~cbp.perception.mapper.SnapshotPublisher.hold_reason`).
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import threading
import time
import uuid
from dataclasses import dataclass, replace
from multiprocessing.connection import Connection, wait
from multiprocessing.process import BaseProcess
from multiprocessing.shared_memory import SharedMemory
from typing import Any, NamedTuple

import numpy as np

from cbp.collision.map_environment import OccupancyEnvironment
from cbp.collision.world import CollisionWorld
from cbp.perception.frame import (
    RENDER_NEAR_FRACTION,
    DepthFrame,
    look_at,
    perspective,
)
from cbp.perception.mapper import (
    Publication,
    SnapshotPublisher,
    cluster_motion,
    integrate_frames,
)
from cbp.perception.motion import ApproachEstimator, MovingCluster, swept_snapshot
from cbp.perception.moving import frame_period, moving_growth, with_moving
from cbp.perception.occupancy import OccupancyGrid
from cbp.robot import FloatArray
from cbp.state import RobotState

__all__ = ["SEGMENT_PREFIX", "SLOTS", "ProcessMapUpdater"]

#: Snapshot slots in shared memory: one being read, one written, one spare.
SLOTS = 3
#: Every segment's name starts with this (then the process id and a token).
SEGMENT_PREFIX = "cbp_map_"
#: How long the child may take to start and load the grid [s].
START_TIMEOUT = 120.0
#: How long :meth:`ProcessMapUpdater.close` waits for the child to end [s].
STOP_TIMEOUT = 5.0


@dataclass(frozen=True)
class _Layout:
    """Where a snapshot's arrays lie in a slot (bytes from its start)."""

    cells: int
    bricks: int

    @property
    def blocked(self) -> int:
        """Offset of the dense obstacle mask (one byte a cell)."""
        return 0

    @property
    def start(self) -> int:
        """Offset of the brick starts (``bricks + 1`` int64)."""
        return _aligned(self.cells)

    @property
    def centres(self) -> int:
        """Offset of the shell's cell centres (at most ``cells`` x 3 float64)."""
        return self.start + 8 * (self.bricks + 1)

    @property
    def size(self) -> int:
        """Bytes in a slot (untouched pages cost no memory)."""
        return self.centres + 24 * self.cells


class _Snapshot(NamedTuple):
    """The child's word that a snapshot is in a slot, and what goes with it."""

    slot: int
    cells: int  # shell cells written
    stamp: float  # capture time of its newest frame [s of the run's clock]
    speeds: FloatArray | None  # the approach estimate per robot shape [m/s]
    moving: list[MovingCluster]  # clusters that move (cluster_motion)
    entered: FloatArray  # centres of the cells something entered lately
    entered_at: float  # when the newest of them was entered [s] (-inf: none)
    taken: int  # frames it took in
    skipped: int  # frames replaced before it took them
    timings: tuple[float, float, float, int]  # received, integrate, snapshot, n


def _aligned(n: int) -> int:
    return (n + 63) // 64 * 64


#: A camera slot's header (float64 each): sequence number, view (16),
#: projection (16), near, far, minimum range, capture time; then the
#: configuration (nq) and the depth image.
_HEADER = 37


def _frame_slot(segment: SharedMemory, nq: int, height: int, width: int) -> np.ndarray:
    """A camera slot's words (float64)."""
    return np.ndarray(_HEADER + nq + height * width, np.float64, buffer=segment.buf)


@dataclass(frozen=True)
class _Setup:
    """What the child needs: the grid and where to write."""

    grid: OccupancyGrid
    settings: Any  # the world's CollisionSettings
    motion_window: float
    cells_name: str
    slot_names: tuple[str, ...]
    layout: _Layout
    cameras: tuple[tuple[str, str, int, int], ...]  # name, segment, height, width
    nq: int


class ProcessMapUpdater(SnapshotPublisher):
    """Integrates depth frames in a child process; same interface as MapUpdater.

    Args:
        grid: the occupancy grid, with what the first frames put in it (the
            child takes it over; from now on this process only reads its
            cells, which move to shared memory).
        world: the collision world whose environment is replaced.
        estimator: the approach estimate to run in the child (its window), or
            None: snapshots as mapped.

    A map that takes each frame at once (for tests and virtual time) is
    :class:`~cbp.perception.mapper.MapUpdater`'s (``synchronous``).

    Raises:
        RuntimeError: the child did not start (its reason).
    """

    def __init__(
        self,
        grid: OccupancyGrid,
        world: CollisionWorld,
        estimator: ApproachEstimator | None = None,
    ) -> None:
        """Create the shared memory, start the child and wait until it is ready."""
        super().__init__()
        self.grid = grid
        self.world = world
        self.estimator = estimator
        self.stamp = self.submitted_t = 0.0
        self._segments: list[SharedMemory] = []
        self._closed = False
        self._lock = threading.Condition()
        self._done = 0  # frames the child has taken (integrated or skipped)
        self._sent = 0
        self._speeds: FloatArray | None = None
        self._moving: list[MovingCluster] = []
        self._entered: FloatArray = np.zeros((0, 3))
        self._entered_at = -np.inf
        self._mapped: OccupancyEnvironment | None = None
        self._process: BaseProcess | None = None
        self._receiver: threading.Thread | None = None
        self._slots: dict[str, np.ndarray] = {}
        self._wake: Any = None
        self._conn: Connection | None = None
        self._send_lock = threading.Lock()
        try:
            self._start(grid, world, estimator)
        except BaseException:
            self.close()
            raise

    def _start(
        self,
        grid: OccupancyGrid,
        world: CollisionWorld,
        estimator: ApproachEstimator | None,
    ) -> None:
        token = f"{SEGMENT_PREFIX}{os.getpid()}_{uuid.uuid4().hex[:8]}"
        cells = SharedMemory(f"{token}_cells", create=True, size=grid.cells.nbytes)
        self._segments.append(cells)
        shared = np.ndarray(grid.cells.shape, np.uint8, buffer=cells.buf)
        shared[...] = grid.cells
        _, dims = grid.bricks
        layout = _Layout(cells=int(grid.cells.size), bricks=int(np.prod(dims)))
        for i in range(SLOTS):
            self._segments.append(
                SharedMemory(f"{token}_slot{i}", create=True, size=layout.size)
            )
        self._layout = layout
        nq = int(world.geometry.robot.model.nq)
        cameras = []
        for i, camera in enumerate(grid.spec.all_cameras):
            words = _HEADER + nq + camera.height * camera.width
            segment = SharedMemory(f"{token}_frame{i}", create=True, size=8 * words)
            self._segments.append(segment)
            slot = _frame_slot(segment, nq, camera.height, camera.width)
            slot[0] = 0.0
            self._slots[camera.name] = slot
            cameras.append((camera.name, segment.name, camera.height, camera.width))
        setup = _Setup(
            grid=grid,  # pickled for the child without its snapshot
            settings=world.settings,
            motion_window=estimator.window if estimator is not None else 0.0,
            cells_name=cells.name,
            slot_names=tuple(s.name for s in self._segments[1 : 1 + SLOTS]),
            layout=layout,
            cameras=tuple(cameras),
            nq=nq,
        )
        context = _context()
        wake = context.Semaphore(0)
        self._wake = wake
        ours, theirs = context.Pipe(duplex=True)
        self._conn = ours
        process = context.Process(
            target=_child,
            args=(setup, wake, theirs),
            name="cbp-map",
            daemon=True,
        )
        process.start()
        self._process = process
        theirs.close()
        ready = wait([ours, process.sentinel], START_TIMEOUT)
        if ours not in ready:
            raise RuntimeError(
                "the map process did not start"
                + (
                    f" (exit code {process.exitcode})"
                    if not process.is_alive()
                    else f" within {START_TIMEOUT:g} s"
                )
            )
        message = ours.recv()
        if message[0] != "ready":
            raise RuntimeError(f"the map process did not start: {message[1]}")
        # From now on this process reads the cells the child writes.
        grid.cells = shared
        self._receiver = threading.Thread(
            target=self._receive, name="cbp-map-receiver", daemon=True
        )
        self._receiver.start()

    # ------------------------------------------------------------------ frames in

    def submit(self, frame: DepthFrame, q: FloatArray, t: float = 0.0) -> None:
        """Queue a frame taken at configuration ``q`` and time ``t`` [s].

        Never waits for the map (nor for a map process that has died).
        """
        self.submitted_t = max(self.submitted_t, t)
        if self.failed is not None or self._closed:
            return
        slot = self._slots.get(frame.camera)
        h, w = frame.depth.shape
        nq = len(slot) - _HEADER - h * w if slot is not None else -1
        if slot is None or nq != len(q):
            raise ValueError(
                f"frame of camera '{frame.camera}' ({w}x{h}) does not fit the map "
                "process's slots (cameras of perception.cameras, their sizes)"
            )
        slot[0] += 1.0  # odd: being written
        slot[1:17] = frame.view.ravel()
        slot[17:33] = frame.projection.ravel()
        slot[33:37] = (frame.near, frame.far, frame.min_range, t)
        slot[_HEADER : _HEADER + nq] = q
        slot[_HEADER + nq :] = frame.depth.ravel()
        slot[0] += 1.0  # even: complete
        with self._lock:
            self._sent += 1
        self._wake.release()

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until the child has taken every frame sent (for tests)."""
        deadline = time.monotonic() + timeout
        with self._lock:
            while self._done < self._sent and self.failed is None:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._lock.wait(left)
        return self.failed is None

    # ------------------------------------------------------------------ snapshots out

    def _receive(self) -> None:
        """Adopt the newest snapshot the child announces, until it ends.

        Snapshots that wait behind a newer one are handed back unread (the
        newer holds their frames too): a control process slower than the
        map adopts the newest map, never a queue of old ones.
        """
        conn, process = self._conn, self._process
        assert process is not None
        assert conn is not None
        while True:
            try:
                ready = wait([conn, process.sentinel])
                if conn not in ready:
                    raise EOFError
                messages = [conn.recv()]
                while conn.poll():
                    messages.append(conn.recv())
            except (EOFError, OSError, ValueError):
                if not self._closed:
                    process.join(1.0)
                    self._fail(f"the map process ended (exit code {process.exitcode})")
                return
            snapshots: list[_Snapshot] = [m[1] for m in messages if m[0] == "snapshot"]
            for message in messages:
                if message[0] == "error":
                    self.error = RuntimeError(message[1])
            for snapshot in snapshots[:-1]:  # older than the newest: unread
                self._send(("free", snapshot.slot))
            if snapshots:
                self._take(snapshots[-1])
            with self._lock:
                for snapshot in snapshots:
                    self._done += snapshot.taken
                    self.skipped += snapshot.skipped
                for message in messages:
                    if message[0] == "error":
                        self._done += message[2]
                self._lock.notify_all()

    def _send(self, message: tuple[str, Any]) -> None:
        """Send to the child (one thread at a time; a child gone is no error).

        A child that has gone is found by the receiver's next wait.
        """
        conn = self._conn
        if conn is None:
            return
        with self._send_lock, contextlib.suppress(OSError, ValueError):
            conn.send(message)

    def _take(self, snapshot: _Snapshot) -> None:
        """Copy a snapshot out of its slot, hand the slot back, adopt it."""
        layout = self._layout
        buf = self._segments[1 + snapshot.slot].buf
        blocked = np.ndarray(
            self.grid.shape, np.bool_, buffer=buf, offset=layout.blocked
        ).copy()
        start = np.ndarray(
            layout.bricks + 1, np.int64, buffer=buf, offset=layout.start
        ).copy()
        centres = np.ndarray(
            (snapshot.cells, 3), np.float64, buffer=buf, offset=layout.centres
        ).copy()
        del buf
        self._send(("free", snapshot.slot))
        try:
            self._adopt(centres, start, blocked, snapshot)
        except Exception as exc:  # reported, the previous map kept
            self.error = RuntimeError(f"failed, previous map kept: {exc!r}")

    def _adopt(
        self,
        centres: FloatArray,
        start: np.ndarray,
        blocked: np.ndarray,
        snapshot: _Snapshot,
    ) -> None:
        """Swap the snapshot into the world, measured ahead by speed x time."""
        stamp = snapshot.stamp
        mapped = self.grid.snapshot_of(centres, start, blocked)
        mapped.stamp = stamp
        self._mapped = mapped
        self._speeds = snapshot.speeds
        self._moving = snapshot.moving
        self._entered = snapshot.entered
        self._entered_at = snapshot.entered_at
        self.world.set_environment(self._ahead(mapped))
        self.stamp = max(self.stamp, stamp)
        self.updates += 1
        received, integrate_s, snapshot_s, frames = snapshot.timings
        self.last_update_s = integrate_s + snapshot_s
        self.published.append(
            Publication(
                stamp, frames, received, integrate_s, snapshot_s, time.perf_counter()
            )
        )

    def _ahead(self, mapped: OccupancyEnvironment) -> OccupancyEnvironment:
        """``mapped`` with each shape's contacts nearer by its approach.

        Over the look-ahead and the snapshot's age (the newest capture time
        submitted less the snapshot's stamp): where the obstacles will be
        when the plan made now has run.
        """
        speeds = self._speeds
        age = max(0.0, self.submitted_t - (mapped.stamp or 0.0))
        horizon = self.look_ahead + age
        out = swept_snapshot(mapped, self._moving, horizon, self.grid.lower)
        if speeds is not None and np.any(speeds > 0):
            out = out.ahead(speeds * horizon)
        grid = self.grid
        out = with_moving(
            out,
            self._entered,
            moving_growth(
                grid.spec.moving_speed,
                self.look_ahead,
                age,
                (mapped.stamp or 0.0) - self._entered_at,
                grid.cell,
                frame_period(grid.spec),
            ),
            grid.cells,
            grid.lower,
        )
        out.stamp = mapped.stamp
        return out

    def age(self) -> float:
        """How much older the snapshot in use is than the newest frame sent [s]."""
        return max(0.0, self.submitted_t - self.stamp)

    # ------------------------------------------------------------------ end

    def _fail(self, reason: str) -> None:
        """The map has stopped for good: say so once, hold the robot."""
        if self.failed is None:
            self.failed = reason
            self.error = RuntimeError(reason)
        with self._lock:
            self._lock.notify_all()

    def close(self) -> None:
        """Stop the child (kill it if it does not stop), free the shared memory.

        Safe to call more than once, and whatever became of the child.
        """
        if self._closed:
            return
        self._closed = True
        process = self._process
        conn = getattr(self, "_conn", None)
        if conn is not None:
            self._send(("stop", None))
        wake = getattr(self, "_wake", None)
        if wake is not None:
            wake.release()
        if process is not None:
            process.join(STOP_TIMEOUT)
            if process.is_alive():
                process.kill()
                process.join(STOP_TIMEOUT)
        self._wake = None  # its semaphore goes with it
        if conn is not None:
            conn.close()
            self._conn = None
        if self._receiver is not None:
            self._receiver.join(STOP_TIMEOUT)
        if process is not None and not process.is_alive():
            process.close()
            self._process = None  # its arguments (the semaphore) go with it
        # The grid keeps a copy of the last cells; then the segments go.
        self._slots = {}
        if self._segments:
            self.grid.cells = np.array(self.grid.cells)
        for segment in self._segments:
            # An array that still views it keeps the mapping until it goes.
            with contextlib.suppress(BufferError):
                segment.close()
            with contextlib.suppress(FileNotFoundError):
                segment.unlink()
        self._segments = []

    def __del__(self) -> None:
        """Never leave a process or a segment behind."""
        if not getattr(self, "_closed", True):
            with contextlib.suppress(Exception):  # at exit, modules may be gone
                self.close()


def _context() -> Any:
    """``forkserver`` (this module preloaded in the server) where there is one."""
    if "forkserver" not in mp.get_all_start_methods():
        return mp.get_context("spawn")
    context = mp.get_context("forkserver")
    context.set_forkserver_preload([__name__])
    return context


# ---------------------------------------------------------------------- the child


def _child(setup: _Setup, wake: Any, conn: Connection) -> None:
    """The map process: integrate the cameras' newest frames, publish to free slots."""
    segments: list[SharedMemory] = []
    grid = setup.grid
    inbox: _Inbox | None = None
    try:
        cells = _attach(setup.cells_name)
        segments.append(cells)
        slots = [_attach(name) for name in setup.slot_names]
        segments.extend(slots)
        inbox = _Inbox(setup)
        segments.extend(inbox.segments)
        grid.cells = np.ndarray(grid.shape, np.uint8, buffer=cells.buf)
        geometry = grid.geometry
        assert geometry is not None
        world = CollisionWorld(geometry, None, setup.settings)
        estimator = (
            ApproachEstimator(world, setup.motion_window)
            if setup.motion_window > 0
            else None
        )
        clusters = cluster_motion(grid) if setup.motion_window > 0 else None
        state = RobotState(geometry.robot)
        # Compile (or load) the kernels now, not at the first frames.
        _warm_up(grid, state)
        warm = grid.environment()
        warm.prepare(geometry.shapes, world.margin(warm))
    except BaseException as exc:
        conn.send(("failed", repr(exc)))
        raise
    conn.send(("ready", None))
    free = list(range(len(slots)))
    mapped: OccupancyEnvironment | None = None
    parent = mp.parent_process()
    try:
        while True:
            woken = wake.acquire(timeout=0.5)
            while wake.acquire(False):  # one pass takes every frame waiting
                pass
            if not _messages(conn, free):
                return  # told to stop
            if parent is not None and not parent.is_alive():
                return
            if not woken:
                continue
            pending, skipped = inbox.take()
            if not pending:
                continue
            taken = len(pending) + skipped
            received = time.perf_counter()
            try:
                integrate_frames(grid, state, pending)
                integrated = time.perf_counter()
                new = grid.environment()
                stamp = max(t for _, _, t in pending)
                speeds = None
                if estimator is not None:
                    try:
                        speeds = estimator.update(stamp, state, mapped, new).copy()
                    except Exception as exc:  # the map itself is still published
                        conn.send(
                            (
                                "error",
                                "approach estimate failed, map published "
                                f"without it: {exc}",
                                0,
                            )
                        )
                moving: list[MovingCluster] = []
                if clusters is not None:
                    try:
                        shapes = geometry.world_shapes(state)
                        moving = clusters.update(stamp, grid.cells, shapes)
                    except Exception as exc:  # the map itself is still published
                        conn.send(
                            (
                                "error",
                                "cluster motion failed, map published "
                                f"without it: {exc}",
                                0,
                            )
                        )
                entered, entered_at = grid.moving(stamp)
                mapped = new
                done = time.perf_counter()
            except Exception as exc:  # reported, the previous map kept
                conn.send(("error", f"failed, previous map kept: {exc!r}", taken))
                continue
            while not free:  # wait for a slot handed back
                if not conn.poll(0.5):
                    if parent is not None and not parent.is_alive():
                        return
                    continue
                if not _messages(conn, free):
                    return
            slot = free.pop(0)
            n = _write(slots[slot], setup.layout, new)
            timings = (received, integrated - received, done - integrated, len(pending))
            conn.send(
                (
                    "snapshot",
                    _Snapshot(
                        slot,
                        n,
                        stamp,
                        speeds,
                        moving,
                        entered,
                        entered_at,
                        taken,
                        skipped,
                        timings,
                    ),
                )
            )
    except (EOFError, BrokenPipeError, KeyboardInterrupt):
        return
    finally:
        grid.cells = np.zeros(0, np.uint8)
        if inbox is not None:
            inbox.views = []
        for segment in segments:
            # A view still alive keeps the mapping until the process ends.
            with contextlib.suppress(BufferError):
                segment.close()


def _warm_up(grid: OccupancyGrid, state: RobotState) -> None:
    """Integrate small frames into a throwaway copy of the grid (compiles).

    A frame of open space, then one in which something came nearer than the
    space seen free (the changed pixels' passes, and the hidden and entered
    cells' ones an obstacle that moves in takes). On a machine's first run
    with cameras (numba compiling every kernel) the map of the generated
    scene moving_11 was behind its cameras from 0.57 s to 5.16 s, and the
    robot stopped; with the second frame, to 2.96 s (one run each; the rest
    not traced). Frames of 8 x 8 pixels were one tile, so the changed
    frame's windowed pass compiled at the first real frame (0.9 s).
    """
    fixed = [c for c in grid.spec.all_cameras if c.parent is None]
    if not fixed:
        return
    # Three tiles across (``perception.kernels``' 16-pixel tiles), so that a
    # change in one corner is a window of the frame, not all of it.
    size = 48
    spec = replace(fixed[0], width=size, height=size)
    near = min(spec.near, RENDER_NEAR_FRACTION * spec.far)
    assert spec.position is not None  # a fixed camera has both
    assert spec.target is not None
    frame = DepthFrame(
        np.full((size, size), 0.999),
        look_at(spec.position, spec.target, spec.up),
        perspective(spec.fov_deg, 1.0, near, spec.far),
        near,
        spec.far,
        "warm-up",
        min_range=spec.near,
    )
    scratch = grid.scratch()
    scratch.integrate(frame, state, 0.0)
    nearer = np.full((size, size), 0.999)
    nearer[2:6, 2:6] = 0.9  # something came between
    scratch.integrate(replace(frame, depth=nearer), state, 0.1)
    scratch.moving_centres(0.1)


def _messages(conn: Connection, free: list[int]) -> bool:
    """Read what the control process sent: slots handed back; False: stop."""
    while conn.poll():
        kind, value = conn.recv()
        if kind == "stop":
            return False
        free.append(value)
    return True


class _Inbox:
    """The cameras' frame slots, read on the child's side."""

    def __init__(self, setup: _Setup) -> None:
        """Open each camera's slot; nothing taken yet."""
        self.nq = setup.nq
        self.segments = [_attach(name) for _, name, _, _ in setup.cameras]
        self.cameras = [(name, h, w) for name, _, h, w in setup.cameras]
        self.views = [
            _frame_slot(segment, setup.nq, h, w)
            for segment, (_, h, w) in zip(self.segments, self.cameras, strict=True)
        ]
        self.seen = [0.0] * len(self.views)

    def take(self) -> tuple[list[tuple[DepthFrame, FloatArray, float]], int]:
        """Each camera's newest complete frame not taken yet, and frames skipped.

        A slot being written (odd sequence number), or rewritten while it was
        copied, is read again.
        """
        taken: list[tuple[DepthFrame, FloatArray, float]] = []
        skipped = 0
        nq = self.nq
        for i, (name, h, w) in enumerate(self.cameras):
            view = self.views[i]
            for _ in range(100):
                seq = float(view[0])
                if seq == self.seen[i]:
                    break
                if seq % 2.0:
                    time.sleep(1e-4)  # being written: a copy takes well under 1 ms
                    continue
                words = view.copy()
                if float(view[0]) != seq:
                    continue
                skipped += int((seq - self.seen[i]) / 2.0) - 1
                self.seen[i] = seq
                frame = DepthFrame(
                    words[_HEADER + nq :].reshape(h, w),
                    words[1:17].reshape(4, 4),
                    words[17:33].reshape(4, 4),
                    float(words[33]),
                    float(words[34]),
                    name,
                    min_range=float(words[35]),
                )
                taken.append((frame, words[_HEADER : _HEADER + nq], float(words[36])))
                break
        return taken, skipped


def _write(segment: SharedMemory, layout: _Layout, env: OccupancyEnvironment) -> int:
    """Write a snapshot's arrays into a slot; the number of shell cells."""
    buf = segment.buf
    assert env.blocked is not None
    mask = env.blocked.mask
    np.ndarray(mask.shape, np.bool_, buffer=buf, offset=layout.blocked)[...] = mask
    start = env.index.start
    np.ndarray(start.shape, np.int64, buffer=buf, offset=layout.start)[...] = start
    centres = env.index.centres
    n = len(centres)
    np.ndarray((n, 3), np.float64, buffer=buf, offset=layout.centres)[...] = centres
    return n


def _attach(name: str) -> SharedMemory:
    """Open a segment the control process created (and owns: it unlinks it).

    The child shares the control process's resource tracker (``spawn`` and
    ``forkserver`` pass it on), so opening registers nothing new.
    """
    return SharedMemory(name)
