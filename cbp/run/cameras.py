# SPDX-License-Identifier: Apache-2.0
"""A run's depth cameras: the frames the robot captured, checked, and mapped.

Each camera captures at its rate on the robot's clock, on the robot's side
of the seam (:class:`~cbp.driver.CameraFrame`, :mod:`cbp.driver.simulated`);
a frame is checked (:meth:`~cbp.perception.frame.DepthFrame.problem`) and
handed with the robot's configuration to the map
(:class:`~cbp.perception.mapper.MapUpdater`): at once on the virtual clock,
the frames of one instant making one snapshot (the map a planner sees then
depends on simulated time only), in the map's worker on the wall clock (never
blocking the loop). A camera whose last valid frame is older than
``perception.camera_timeout`` holds the robot until it gives one again. A
frame is valid when it is well formed
(:meth:`~cbp.perception.frame.DepthFrame.problem`) and believable
(:mod:`cbp.perception.plausibility`: not blind, not frozen, not seeing
through the robot).

The map's bounds default to the box the arm can reach
(:func:`~cbp.scenario.reach.reach_box`); space outside them is unknown. A
camera that sees surfaces outside them within that box (where the arm could
meet them, but the map cannot hold them) says so, once, in an event.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from cbp.collision.objects import PrimitiveEnvironment
from cbp.collision.world import CollisionWorld
from cbp.driver import CameraFrame
from cbp.methods.settings import ClockKind
from cbp.perception.frame import DepthFrame
from cbp.perception.kernels import UNKNOWN
from cbp.perception.map_process import ProcessMapUpdater
from cbp.perception.mapper import MapUpdater
from cbp.perception.motion import ApproachEstimator
from cbp.perception.moving import PREPARED_LOOK_AHEAD, prepare_moving_tables
from cbp.perception.occupancy import OccupancyGrid
from cbp.perception.plausibility import FrameCheck, PlausibilityLimits
from cbp.perception.spec import CameraSpec, PerceptionSpec
from cbp.robot import FloatArray
from cbp.run.events import RunLog
from cbp.run.robot_link import RobotLink
from cbp.run.separation import SeparationMonitor
from cbp.scenario.reach import Bounds, reach_box
from cbp.state import RobotState

__all__ = ["KEPT_CAPTURES", "Cameras"]

#: Capture times kept per camera (:meth:`Cameras.mapped_since` counts up to it).
KEPT_CAPTURES = 16

#: A camera's frames are searched for surfaces outside the map's bounds this
#: often [s], every :data:`OUTSIDE_STRIDE`-th pixel both ways; at least
#: :data:`OUTSIDE_READINGS` such readings are said.
OUTSIDE_EVERY, OUTSIDE_STRIDE, OUTSIDE_READINGS = 1.0, 4, 4

#: Readings within this of a robot shape's bounding sphere are the robot's,
#: not a surface outside the bounds [m].
OUTSIDE_ROBOT_MARGIN = 0.05


class Cameras:
    """The depth cameras of a run and the map they feed.

    A camera without a valid frame for ``perception.camera_timeout``, a map
    that failed (its process ended) or lags that far behind the cameras holds
    the robot (:meth:`hold_reason`).

    Args:
        arm: the robot, whose cameras capture the frames.
        spec: the scenario's ``perception:`` section.
        world: the collision world whose environment becomes the map's
            snapshots.
        clock: ``virtual`` integrates each frame as it is captured, ``wall``
            in the map's worker.
        log: the run's log, for events.
        predict_motion: measure how fast mapped obstacles approach the robot
            (``collision.predict_motion``).

    The robot looks once before it moves: every camera's first frame is in the
    map when this returns.

    Attributes:
        cameras: the cameras, in the scenario's order.
        mapper: the map updater.
    """

    def __init__(
        self,
        arm: RobotLink,
        spec: PerceptionSpec,
        world: CollisionWorld,
        clock: ClockKind,
        log: RunLog,
        predict_motion: bool,
    ) -> None:
        """Build the grid; map the first frames."""
        robot = world.geometry.robot
        arm.refresh()
        #: The box the arm can reach (None: no fixed reach).
        self.reach = reach_box(world.geometry, arm.q.copy())
        if spec.bounds is None and self.reach is not None:
            spec = spec.with_bounds(*self._whole_cells(self.reach, spec.cell_size))
        self._spec = spec
        self._log = log
        self._state = RobotState(robot)
        world.set_environment(PrimitiveEnvironment([]))
        self.cameras: list[CameraSpec] = list(spec.all_cameras)
        self._index = {c.name: i for i, c in enumerate(self.cameras)}
        n = len(self.cameras)
        limits = PlausibilityLimits(
            spec.max_far_fraction, spec.see_through_fraction, spec.see_through_tolerance
        )
        self._checks = [
            FrameCheck(c.name, c.parent is not None, limits) for c in self.cameras
        ]
        #: Per camera: time of its last valid frame, and whether it is failing.
        self._last_valid = [0.0] * n
        self._failing = [False] * n
        #: Per camera: when its frames are next searched for surfaces outside
        #: the bounds (inf: said already).
        self._outside_next = [0.0] * n
        self._stale: str | None = None
        grid = self._grid = OccupancyGrid(spec, world.geometry)
        first = MapUpdater(grid, world, synchronous=True)
        for captured in arm.frames():
            frame = self._checked_frame(captured)
            if frame is not None:
                first.submit(frame, captured.q.copy())
        estimator = (
            ApproachEstimator(world, spec.motion_window)
            if spec.motion_window > 0 and predict_motion
            else None
        )
        if clock != "virtual":
            # The moving cells' tables, before the clock starts: built when the
            # first obstacle sets off, they held up the map's snapshots.
            prepare_moving_tables(
                world.geometry.shapes,
                world.margin(grid.environment()),
                grid.cell,
                spec.moving_speed,
                PREPARED_LOOK_AHEAD + spec.camera_timeout,
            )
        # Wall clock: the map in a process of its own unless
        # perception.map_process is off (the interpreter lock would make the
        # loop and a map thread wait for each other); virtual: in the loop.
        updater = (
            ProcessMapUpdater if spec.map_process and clock != "virtual" else MapUpdater
        )
        self.mapper: MapUpdater | ProcessMapUpdater = (
            MapUpdater(
                grid,
                world,
                synchronous=True,
                estimator=estimator,
                latency=spec.virtual_latency,
                batch=True,
            )
            if clock == "virtual"
            else updater(grid, world, estimator=estimator)
        )
        #: Per camera: capture times of its latest frames handed to the map.
        self._submitted: list[deque[float]] = [
            deque(maxlen=KEPT_CAPTURES) for _ in self.cameras
        ]
        #: Says when a moving obstacle comes nearer than the arm can afford.
        self.separation = SeparationMonitor(world, log, spec.moving_speed)

    @property
    def grid(self) -> OccupancyGrid:
        """The occupancy grid the cameras feed."""
        return self.mapper.grid

    def unseen(self, points: FloatArray) -> np.ndarray:
        """Which points (n, 3) lie in unseen space that counts as an obstacle.

        Space no camera has seen and the robot has not held; all False with
        ``perception.unknown: free``.
        """
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if not self._spec.unknown_blocks:
            return np.zeros(len(points), dtype=bool)
        return np.asarray(self.mapper.grid.state_at(points) == UNKNOWN)

    def take(
        self, frames: list[CameraFrame], t: float, q: FloatArray, look_ahead: float
    ) -> None:
        """Check the frames the robot captured up to ``t`` and hand them to the map.

        Args:
            frames: the frames, oldest first.
            t: the robot's time now [s].
            q: the robot's joint positions now.
            look_ahead: how far ahead the map measures approaching obstacles
                [s] (the plan being made runs that long).
        """
        self.mapper.look_ahead = look_ahead
        for captured in frames:
            frame = self._checked_frame(captured)
            if frame is not None:
                self.mapper.submit(frame, captured.q.copy(), captured.stamp)
                self._submitted[self._index[captured.camera]].append(captured.stamp)
            self._say_map_error(t)
        self.mapper.release(t)  # the last instant's snapshot (batch)
        self._say_map_error(t)
        self.separation.check(t, q)

    def _say_map_error(self, t: float) -> None:
        if self.mapper.error is not None:
            error, self.mapper.error = self.mapper.error, None
            self._log.event(t, f"map update: {error}")

    def mapped_since(self, name: str, t: float) -> int:
        """How many frames of camera ``name`` captured at or after ``t`` are mapped.

        A frame counts once the map has published a snapshot as new as its
        capture (a frame the map skipped for a newer one of the same camera
        counts too: the newer one carries what it saw). Counts up to
        :data:`KEPT_CAPTURES`.
        """
        i = self._index[name]
        stamp = self.mapper.stamp
        return sum(1 for c in self._submitted[i] if t - 1e-9 <= c <= stamp + 1e-9)

    def hold_reason(self, t: float) -> str | None:
        """Why the robot must hold at ``t``, or None.

        A camera whose last valid frame is older than
        ``perception.camera_timeout`` holds the robot until it gives one again
        (the map would otherwise go stale where the robot is heading). Each
        change is an event.
        """
        timeout = self._spec.camera_timeout
        stale = [
            camera.name
            for camera, last in zip(self.cameras, self._last_valid, strict=True)
            if t - last > timeout
        ]
        reason = (
            f"no valid frame from camera {', '.join(repr(n) for n in stale)} for "
            f"more than {timeout:g} s: robot stopped"
            if stale
            else self.mapper.hold_reason(timeout)  # the map failed, or lags
        )
        if reason != self._stale:
            self._log.event(
                t, reason or "every camera gives valid frames: robot resumes"
            )
            self._stale = reason
        return reason

    def close(self) -> None:
        """Stop the map's worker."""
        self.mapper.close()

    def _checked_frame(self, captured: CameraFrame) -> DepthFrame | None:
        """The captured frame if it is valid; else None and an event.

        A frame is valid when at least ``perception.min_valid_fraction`` of its
        pixels hold a reading (:meth:`DepthFrame.problem`) and it is believable
        (:mod:`cbp.perception.plausibility`). The first bad frame of a run of
        them is an event, and so is the first good one after.
        """
        i, t, frame = self._index[captured.camera], captured.stamp, captured.frame
        self._state.update(captured.q.copy())
        problem: str | None
        if frame is None:
            problem = f"capture failed ({captured.problem})"
        else:
            try:
                problem = frame.problem(self._spec.min_valid_fraction)
                if problem is None:
                    problem = self._checks[i].check(
                        frame,
                        self._state.q,
                        self._joint_positions(),
                        self._grid.occupied_in_view,
                    )
            except Exception as exc:  # a frame that cannot be checked is dropped
                problem = f"check failed ({type(exc).__name__}: {exc})"
        name = captured.camera
        if problem is None:
            assert frame is not None
            if t >= self._outside_next[i]:
                self._outside_next[i] = t + OUTSIDE_EVERY
                self._say_outside(i, frame, t)
            if self._failing[i]:
                self._log.event(t, f"camera '{name}' gives valid frames again")
                self._failing[i] = False
            self._last_valid[i] = t
            return frame
        if not self._failing[i]:
            self._log.event(t, f"camera '{name}': frame dropped, {problem}")
            self._failing[i] = True
        return None

    @staticmethod
    def _whole_cells(box: Bounds, cell: float) -> Bounds:
        """``box`` grown to whole cells from a multiple of ``cell`` [m]."""
        lower = np.floor(box[0] / cell) * cell
        upper = np.ceil(box[1] / cell) * cell
        return lower, upper

    def _say_outside(self, i: int, frame: DepthFrame, t: float) -> None:
        """Say (once per camera) that ``frame`` sees surfaces outside the bounds.

        Readings outside the map's bounds, within the box the arm can reach
        (:attr:`reach`; anywhere when None), and not the robot's (farther than
        :data:`OUTSIDE_ROBOT_MARGIN` from its shapes' bounding spheres).
        """
        grid = self._grid
        lower, upper = grid.bounds
        points, hit = frame.points(OUTSIDE_STRIDE)
        points = points[hit]
        out = np.any((points < lower) | (points > upper), axis=1)
        if self.reach is not None:
            out &= np.all((points >= self.reach[0]) & (points <= self.reach[1]), axis=1)
        points = points[out]
        if len(points) and grid.geometry is not None:
            shapes = grid.geometry.world_shapes(self._state)
            gap = np.linalg.norm(points[:, None] - shapes.centres[None], axis=2)
            near = gap < shapes.radii + OUTSIDE_ROBOT_MARGIN
            points = points[~near.any(axis=1)]
        if len(points) < OUTSIDE_READINGS:
            return
        self._outside_next[i] = np.inf
        lo, hi = points.min(axis=0), points.max(axis=0)
        self._log.event(
            t,
            f"camera '{frame.camera}' sees surfaces outside the map's bounds "
            f"{np.round(lower, 3).tolist()}...{np.round(upper, 3).tolist()} m "
            f"within the arm's reach (readings from {np.round(lo, 2).tolist()} to "
            f"{np.round(hi, 2).tolist()} m): the map holds them as unknown "
            "space (perception.bounds)",
        )

    def _joint_positions(self) -> FloatArray:
        """Where the robot's joints are at the last capture, (n, 3) [m]."""
        placements = self._state.data.oMi
        return np.array([placements[j].translation for j in range(1, len(placements))])
