# SPDX-License-Identifier: Apache-2.0
"""A three-state occupancy grid (unknown, free, occupied) updated from depth frames.

Every cell starts **unknown**. A frame marks the cells it sees *through* free (the
measured surface along their pixel lies more than a cell beyond them) and the
cells its readings fall in **occupied**; an occupied cell seen through
``misses_to_clear`` times becomes free again (a removed obstacle). The space the
robot's padded shapes hold is free too, with two cells more at the first frame (a
run starts clear): the robot was there. Nothing more: space beside the arm that
no camera sees (its own shadow) stays unknown, so the arm never creeps into it a
frame at a time (``robot_space``). With ``perception.unknown: occupied`` (the
default) unknown cells are obstacles for every collision-aware method, so the
arm never moves into space nothing has seen: the far side of an obstacle, its
shadow, or what the arm itself hides.

An obstacle that moves shows the cameras its faces, not the rest of it, and
the rest moves into space they saw free before. So each fixed camera keeps, per
pixel, the range it saw free along it: where a reading (not the robot's) comes
more than two cells nearer, something came between, and the free cells behind
it are **unknown** again, up to the robot's padded shapes (what lies behind the
robot was hidden by the robot). This repeats at every frame while the reading
moves and for ``shadow_hold`` seconds after; then the space behind it is an
ordinary shadow. A fixed camera that was moved starts its pixels over; cameras
mounted on the robot keep none (their view moves with the arm).

Why not OctoMap: ray-cast insertion of one 320x240 frame takes 120-250 ms on this
machine and its default clamping keeps a moved obstacle for about nine frames
(``../shared/notes/perception.md``). Here each pass is a compiled loop over the
grid (:mod:`cbp.perception.kernels`): the cells of the frustum are projected into
the image (free cells skipped), the robot's points are filtered out against its
shapes, and the snapshot for the collision world indexes only the **shell** of the
obstacle cells, those next to open space, so a solid block of unknown space costs
its surface, not its volume.

Robot pixels: their readings are not inserted, but the space in front of them
along their rays is seen, so the robot never clears what it hides.

A camera's frame from the view of its last one is integrated only where it
changed (``perception.whole_frame_every``): the pixels whose reading moved
beyond the noise, the space seen through over the image's tiles around them
and over the bricks whose cells changed since the camera's last frame
(:func:`~cbp.perception.kernels.frame_changes`,
:func:`~cbp.perception.kernels.mark_seen`); each unchanged reading keeps its
cell occupied. The rest would do what it did at the camera's last frame: on
exact frames the map is the one whole frames give.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cbp.collision.cell_index import BRICK, MAX_BRICKS, CellIndex
from cbp.collision.cell_kernels import SLOT_BRICK
from cbp.collision.geometry import RobotGeometry, WorldShapes
from cbp.collision.map_environment import (
    BlockedGrid,
    MetaballRefiner,
    OccupancyEnvironment,
)
from cbp.perception.frame import DepthFrame
from cbp.perception.kernels import (
    KEPT_NONE,
    OCCUPIED,
    UNKNOWN,
    FrameArrays,
    GridArrays,
    KeptPixels,
    PixelHistory,
    RobotShapes,
    carve_shapes,
    eroded_ranges,
    eroded_ranges_in,
    frame_changes,
    insert_readings,
    mark_seen,
    merge_entered,
    occupied_centres,
    shell_update,
    tile_windows,
)
from cbp.perception.spec import PerceptionSpec
from cbp.robot import FloatArray
from cbp.state import RobotState

__all__ = ["FrameSummary", "OccupancyGrid"]

#: With ``robot_space: nearby``, how far beyond the padded shapes the robot's
#: presence frees unseen space (and one cell more) [m].
NEARBY_MARGIN = 0.02

#: The self-filter's shapes when there is no robot.
_NO_ROBOT = RobotShapes(
    np.zeros((0, 4)),
    np.zeros(1, np.int64),
    np.zeros((0, 3)),
    np.zeros(0),
    np.zeros(0),
    np.zeros(0),
)


#: Pixels a side of the tiles a frame is seen through by (only the tiles
#: where its readings changed, :func:`~cbp.perception.kernels.frame_changes`).
TILE = 16

#: A camera's pixel history when hidden space is not tracked.
_UNTRACKED = PixelHistory(np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0)))


@dataclass(frozen=True)
class FrameSummary:
    """What one frame did to the map.

    Attributes:
        camera: the camera's name.
        valid_fraction: pixels with a valid reading (finite, in range), of all.
        robot_points: readings filtered out as the robot.
        inserted: readings inserted as obstacles.
        seen: cells whose state the frame changed by seeing through them.
        carved: unknown cells made free because the robot held them.
        hidden: free cells made unknown because something came between them
            and the camera.
    """

    camera: str
    valid_fraction: float
    robot_points: int
    inserted: int
    seen: int
    carved: int
    hidden: int = 0


@dataclass
class _Prepared:
    """One frame as :meth:`OccupancyGrid.integrate_together` passes it on."""

    frame: DepthFrame
    t: float | None
    readings: FrameArrays
    robot: RobotShapes
    kept: KeptPixels
    todo: np.ndarray
    motion: FloatArray
    windows: np.ndarray
    since: int
    tiles: np.ndarray
    carved: int
    valid: int = 0
    removed: int = 0
    inserted: int = 0
    hidden: int = 0


class OccupancyGrid:
    """A dense three-state voxel grid over the mapped region.

    The grid covers the spec's bounds (:attr:`PerceptionSpec.region`) and a
    layer of cells around them that no camera sees through and the robot never
    frees: space outside the bounds is unknown, as is space no camera has
    seen, and with ``unknown: occupied`` the arm stays within the bounds. (It
    was free: a box wholly below a map's floor was "reached" with the hand
    inside its padding.)

    Args:
        spec: resolution, bounds, range, clearing and unknown-space settings.
        geometry: the robot's shapes, for filtering it out and for the space it
            holds (None: no robot).

    Attributes:
        cells: cell states (nx, ny, nz): :data:`~cbp.perception.kernels.UNKNOWN`,
            ``FREE`` or ``OCCUPIED``; from :attr:`lower` (a cell outside the
            bounds) to :attr:`upper`.
        bounds: the mapped region's lower and upper corners (3,) each [m]
            (the spec's, its size rounded up to whole cells).
        frames: frames integrated so far.
        robot_points_removed: readings filtered out as the robot, over all frames.
        hidden_cells: free cells made unknown again because something came
            between them and a camera, over all frames.
        last: the last frame's :class:`FrameSummary`.

    Moving obstacles: a reading that comes nearer than the space its pixel saw
    free (the same test that hides the space behind it) falls in a cell that
    something *entered*. Those cells are kept with the time they were last
    entered; :meth:`moving_centres` gives the ones still occupied and entered
    within ``shadow_hold`` seconds: the leading surfaces of what moves, which
    the map updaters measure ahead (:mod:`cbp.perception.moving`).
    """

    def __init__(self, spec: PerceptionSpec, geometry: RobotGeometry | None) -> None:
        """Allocate the grid, all unknown."""
        self.spec = spec
        self.cell = spec.cell_size
        # The mapped region, and a layer of cells around it that stays
        # unknown: the space outside the bounds (no pass sees through it or
        # frees it; a reading may make it occupied).
        region = np.asarray(spec.region, dtype=float)
        inner = np.ceil((region[1] - region[0]) / self.cell).astype(int)
        self.bounds = (region[0], region[0] + inner * self.cell)
        self.lower = region[0] - self.cell
        self.shape = tuple(int(n) + 2 for n in inner)
        self.upper = self.lower + np.array(self.shape) * self.cell
        self.cells = np.full(self.shape, UNKNOWN, dtype=np.uint8)
        self.misses = np.zeros(self.shape, dtype=np.uint8)
        self.geometry = geometry
        self.frames = 0
        self.robot_points_removed = 0
        self.hidden_cells = 0
        self.last: FrameSummary | None = None
        self._started = False  # the robot's first space has been freed
        if geometry is not None:  # the shapes' boxes in their frames (carving)
            lower = np.array([s.lower for s in geometry.shapes]).reshape(-1, 3)
            upper = np.array([s.upper for s in geometry.shapes]).reshape(-1, 3)
            self._box_centres = 0.5 * (lower + upper)
            self._box_halves = 0.5 * (upper - lower)
        # The self-filter's reach around each robot shape [m].
        self._robot_reach = (
            np.ascontiguousarray(geometry.visual_excess + spec.robot_margin)
            if geometry is not None
            else np.zeros(0)
        )
        brick = BRICK
        dims = -(-np.array(self.shape) // brick)
        while np.prod(dims) > MAX_BRICKS:
            brick *= 2
            dims = -(-np.array(self.shape) // brick)
        self._brick = brick
        self._dims = dims
        # The snapshot's bookkeeping (shell_update): the blocked mask, the bricks
        # changed since the last snapshot, and the last shell.
        self._blocked = np.zeros(self.shape, dtype=np.bool_)
        self._dirty = np.ones(tuple(int(n) for n in dims), dtype=np.bool_)
        # Per brick: all its cells were free at the last snapshot (mark_seen
        # skips such bricks while they are not dirty).
        self._clear = np.zeros(tuple(int(n) for n in dims), dtype=np.bool_)
        # Per brick: the frame a cell of it last changed state or misses in
        # (frames counted in _clock[0]; mark_seen sees through those again).
        self._stamp = np.zeros(tuple(int(n) for n in dims), dtype=np.int64)
        self._clock = np.zeros(1, dtype=np.int64)
        self._shell = (
            np.empty((0, 3)),
            np.zeros(int(np.prod(dims)) + 1, np.int64),
            np.zeros(int(np.prod(dims)) if brick == SLOT_BRICK else 0, np.uint64),
        )
        self._snapshot: OccupancyEnvironment | None = None
        self._mounted = {c.name for c in spec.all_cameras if c.parent is not None}
        self._noise = {c.name: c.noise for c in spec.all_cameras}
        # Per camera: the view its pixel history was taken from, and the history.
        self._moved: dict[str, tuple[FloatArray, PixelHistory]] = {}
        # How far beyond each robot shape hidden space stops: its padding and
        # two cells. The contact rows hold the arm a cell from a cell's
        # centre (half a cell of inflation, half the cell's size), and the
        # march that hides a ray's cells stops at a point up to a cell from
        # the centre of the cell it hides last. Hidden space that came within
        # that pushed the arm away from it, frame after frame, while what hid
        # it moved: a post receding from the hand along a camera's rays
        # pushed the hand 6 cm off its goal. (The robot's first frame frees
        # as much.)
        self._held = (
            np.full(len(geometry.shapes), geometry.padding + 2.0 * self.cell)
            if geometry is not None
            else np.zeros(0)
        )
        # The cells entered by a frame (the kernel's output), and those entered
        # lately: flat indices and the last time each was entered [s].
        self._entered = np.empty(0, np.int64)
        self._recent = (np.zeros(0, np.int64), np.zeros(0))
        # Per camera: the view its kept pixels were taken from, what they last
        # gave the map, and its frames since the last one integrated whole.
        self._kept: dict[
            str,
            tuple[
                FloatArray,
                KeptPixels,
                int,
                tuple[FloatArray, FloatArray] | None,
                int,
            ],
        ] = {}
        #: Frames integrated whole, and only where they changed.
        self.whole_frames = 0
        self.changed_frames = 0

    # ------------------------------------------------------------------ copies

    def __getstate__(self) -> dict[str, object]:
        """Copied or pickled without the last snapshot.

        (It holds compiled queries and maybe a coal octree; the copy builds
        its own at its first :meth:`environment`.) The map process takes its
        grid this way.
        """
        state = dict(self.__dict__)
        state["_snapshot"] = None
        return state

    def scratch(self) -> OccupancyGrid:
        """A copy whose integration changes nothing of this grid (warm-ups)."""
        state = self.__getstate__()
        state["cells"] = self.cells.copy()
        state["misses"] = self.misses.copy()
        state["_dirty"] = self._dirty.copy()
        state["_clear"] = self._clear.copy()
        state["_stamp"] = self._stamp.copy()
        state["_clock"] = self._clock.copy()
        state["_blocked"] = self._blocked.copy()
        state["_moved"] = {}
        state["_kept"] = {}
        state["_entered"] = np.empty(0, np.int64)
        state["_recent"] = (np.zeros(0, np.int64), np.zeros(0))
        out = OccupancyGrid.__new__(OccupancyGrid)
        out.__dict__.update(state)
        return out

    # ------------------------------------------------------------------ reading

    def centres(self, state: int = OCCUPIED) -> FloatArray:
        """Centres of the cells in ``state`` (N, 3) [m] (default: occupied)."""
        idx = np.argwhere(self.cells == state)
        return np.asarray(self.lower + (idx + 0.5) * self.cell)

    def moving_centres(self, t: float) -> FloatArray:
        """Centres of the occupied cells something entered lately (N, 3) [m].

        Entered (see the class) at most ``shadow_hold`` seconds before ``t``,
        and occupied still: what moves into space the cameras saw free.
        """
        flat, when = self._recent
        oldest = t - self.spec.shadow_hold
        return occupied_centres(flat, when, oldest, self.cells, self.lower, self.cell)

    def moving(self, t: float) -> tuple[FloatArray, float]:
        """:meth:`moving_centres`, and when the newest of them was entered [s].

        -inf when there are none. How long nothing has been entered bounds
        how fast what the cameras saw move still moves
        (:func:`~cbp.perception.moving.moving_growth`).
        """
        centres = self.moving_centres(t)
        flat, when = self._recent
        if not len(centres) or not len(flat):
            return centres, -np.inf
        live = (when >= t - self.spec.shadow_hold) & (
            self.cells.reshape(-1)[flat] == OCCUPIED
        )
        return centres, float(when[live].max()) if live.any() else -np.inf

    def _remember_entered(self, n: int, t: float) -> None:
        """Keep the ``n`` cells the last frame entered, at time ``t``."""
        flat, when = self._recent
        oldest = t - self.spec.shadow_hold
        self._recent = merge_entered(flat, when, self._entered[:n], t, oldest)

    @property
    def arrays(self) -> GridArrays:
        """The grid's arrays as the compiled passes take them.

        Built at each call (a few microseconds): the map process swaps
        :attr:`cells` for shared memory.
        """
        return GridArrays(
            self.cells,
            self.misses,
            self.lower,
            float(self.cell),
            self._dirty,
            int(self._brick),
            self._clear,
            self._stamp,
            self._clock,
        )

    def count(self, state: int) -> int:
        """Number of cells in ``state``."""
        return int(np.count_nonzero(self.cells == state))

    def occupied_in_view(self, frame: DepthFrame, stride: int = 16) -> float:
        """The fraction of ``frame``'s view in which the map holds an obstacle.

        Along the rays of every ``stride``-th pixel (both ways), from the
        camera to the far plane in half-cell steps: the fraction of rays that
        meet a cell the grid holds occupied. What a camera that reads
        nothing there contradicts (:class:`~cbp.perception.plausibility.FrameCheck`).
        """
        h, w = frame.depth.shape
        u = np.arange(stride // 2, w, stride)
        v = np.arange(stride // 2, h, stride)
        x = 2.0 * (u + 0.5) / w - 1.0
        y = 2.0 * (h - 1 - v + 0.5) / h - 1.0
        X, Y = np.meshgrid(x, y)
        far = np.stack([X, Y, np.ones_like(X), np.ones_like(X)], -1).reshape(-1, 4)
        far = far.dot(frame.unprojection.T)
        far = far[:, :3] / far[:, 3:4]
        start = frame.position
        length = float(np.max(np.linalg.norm(far - start, axis=1)))
        steps = np.arange(0.0, 1.0, 0.5 * self.cell / max(length, self.cell))
        points = start + steps[None, :, None] * (far - start)[:, None, :]
        met = self.state_at(points.reshape(-1, 3)) == OCCUPIED
        return float(np.mean(met.reshape(len(far), -1).any(axis=1)))

    def state_at(self, points: FloatArray) -> np.ndarray:
        """The state of the cell of each point (n, 3); outside the grid: UNKNOWN.

        (Outside the mapped region nothing is seen: it may hold anything.)
        """
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        idx = np.floor((points - self.lower) / self.cell).astype(np.intp)
        inside = np.all((idx >= 0) & (idx < np.array(self.shape)), axis=1)
        out = np.full(len(points), UNKNOWN, dtype=np.uint8)
        i = idx[inside]
        out[inside] = self.cells[i[:, 0], i[:, 1], i[:, 2]]
        return out

    # ------------------------------------------------------------------ updates

    def integrate(
        self, frame: DepthFrame, state: RobotState | None, t: float | None = None
    ) -> FrameSummary:
        """Add one frame: the robot's space, the space seen through, the readings.

        Args:
            frame: the depth image.
            state: the robot at capture time, for the self-filter and the space
                it holds (None: no robot).
            t: the frame's time [s]; with it, space the camera saw free and now
                sees hidden behind something that came between is unknown
                again (``perception.shadow_hold``; the module's docstring).
                None: not tracked for this frame.
        """
        return self.integrate_together([(frame, state, t)])[0]

    def integrate_together(
        self, frames: list[tuple[DepthFrame, RobotState | None, float | None]]
    ) -> list[FrameSummary]:
        """Add frames captured at one instant: readings first, then what each sees.

        Each frame's robot space and readings (and the space they hide), then
        the space each sees through: a cell one camera sees through is free at
        that instant, whatever another camera's nearer reading hides behind
        it. Frame by frame, a cell seen through by one camera and then hidden
        by the next was unknown in the snapshot, and back and forth at every
        frame while the surface that hid it moved or stood within
        ``shadow_hold``: beside a hand whose goal a post had just passed,
        200-600 cells near the hand flipped at every instant and held it
        6 cm off its goal. ``state`` is read at once (it may be updated for
        the next frame).
        """
        prepared = [self._prepare(frame, state, t) for frame, state, t in frames]
        seen = {}
        if len(prepared) == 1:  # one frame: what it sees and hides are apart
            seen[0] = self._see(prepared[0])
        for p in prepared:
            self._insert(p)
        out = []
        for k, p in enumerate(prepared):
            if k not in seen:
                seen[k] = self._see(p)
            self.frames += 1
            self.last = FrameSummary(
                camera=p.frame.camera,
                valid_fraction=p.valid / p.frame.depth.size
                if p.frame.depth.size
                else 0.0,
                robot_points=p.removed,
                inserted=p.inserted,
                seen=seen[k],
                carved=p.carved,
                hidden=p.hidden,
            )
            out.append(self.last)
        return out

    def _prepare(
        self, frame: DepthFrame, state: RobotState | None, t: float | None
    ) -> _Prepared:
        """A frame as the passes take it, and the robot's space freed."""
        self._clock[0] += 1  # this frame's stamp (before the passes)
        robot = _NO_ROBOT
        carved = 0
        shapes = None
        if state is not None and self.geometry is not None:
            shapes = self.geometry.world_shapes(state)
            carved = self.carve_robot(state, shapes)
            robot = RobotShapes(
                shapes.planes,
                shapes.plane_start,
                shapes.centres,
                shapes.radii,
                self._robot_reach,
                self._held,
            )
        depth = np.ascontiguousarray(frame.depth, dtype=float)
        nearest, far_plane, far_buffer = frame.buffer_limits
        if self._entered.size < depth.size:  # one entry a pixel at most
            self._entered = np.empty(depth.size, np.int64)
        clip = frame.projection.dot(frame.view)[[0, 1, 3]]
        readings = FrameArrays(
            depth,
            frame.unprojection,
            np.ascontiguousarray(clip),
            np.ascontiguousarray(frame.view[2]),
            nearest,
            far_plane,
            far_buffer,
            np.ascontiguousarray(frame.position),
            float(self.spec.max_range),
            self._spread(frame),
        )
        kept, since, motion = self._kept_pixels(frame, shapes)
        whole = since < 0
        todo, tiles = frame_changes(readings, kept, whole, TILE, 0.5 * self.cell)
        h, w = depth.shape
        windows = (
            np.array([[0, w, 0, h]], dtype=np.int64)
            if whole
            else tile_windows(tiles, TILE, h, w)
        )
        return _Prepared(
            frame, t, readings, robot, kept, todo, motion, windows, since, tiles, carved
        )

    def _see(self, p: _Prepared) -> int:
        """The space the frame sees through (:meth:`_see_through`)."""
        return self._see_through(
            p.frame, p.readings, p.frame.buffer_limits, p.windows, p.since, p.tiles
        )

    def _insert(self, p: _Prepared) -> None:
        """The frame's readings into the grid (and the space they hide)."""
        t = p.t
        valid, removed, inserted, hidden, entered = insert_readings(
            p.readings,
            p.robot,
            self.arrays,
            self._pixels(p.frame, t),
            0.0 if t is None else float(t),
            float(self.spec.shadow_hold),
            self._entered,
            p.todo,
            p.kept,
            p.motion,
        )
        if t is not None:
            self._remember_entered(entered, t)
        self.robot_points_removed += removed
        self.hidden_cells += hidden
        p.valid, p.removed, p.inserted, p.hidden = valid, removed, inserted, hidden

    def _spread(self, frame: DepthFrame) -> FloatArray:
        """How far the camera noise spreads a reading: self-filter, hidden space.

        ``map_sigmas`` times the camera's sigma(z) (its
        :class:`~cbp.perception.spec.DepthNoise`), as :func:`insert_readings`
        takes it; zeros for a camera without noise or not in the spec.
        """
        noise = self._noise.get(frame.camera)
        if noise is None or not noise.enabled:
            return np.array([frame.near, frame.far, 0.0, 0.0, 0.0])
        k = noise.map_sigmas
        return np.array(
            [frame.near, frame.far, k * noise.sigma_0, k * noise.sigma_growth, noise.z0]
        )

    def _kept_pixels(
        self, frame: DepthFrame, shapes: WorldShapes | None
    ) -> tuple[KeptPixels, int, FloatArray]:
        """The camera's kept pixels, the frame of its last one (-1: whole), motion.

        The frame (the grid's clock) of the camera's last frame: the bricks
        stamped since are seen through again (:func:`mark_seen`); -1: this
        frame is integrated whole, as the camera's first frame from its view
        (a fixed camera that was moved, a mounted one whenever the arm moved:
        begun anew) and every ``whole_frame_every``-th after
        (:attr:`PerceptionSpec.whole_frame_every`).
        Motion: per robot shape, how far its sphere centre moved since the
        camera's last frame [m] and the angle it turned [rad]
        (:func:`~cbp.perception.kernels.insert_readings`); inf when not known.
        """
        entry = self._kept.get(frame.camera)
        shape = frame.depth.shape
        if (
            entry is None
            or entry[1].range.shape != shape
            or not np.array_equal(entry[0], frame.view)
        ):
            kept = KeptPixels(
                np.full(shape, np.nan),
                np.full(shape, KEPT_NONE, dtype=np.int64),
                np.zeros(shape, dtype=np.bool_),
                np.zeros(shape),
                np.zeros(shape),
            )
            count = 0
            before = None
            last = -1
        else:
            kept, count, before, last = entry[1], entry[2], entry[3], entry[4]
        n = 0 if shapes is None else len(shapes.radii)
        motion = np.full((n, 2), np.inf)
        if shapes is not None and before is not None and len(before[0]) == n:
            motion[:, 0] = np.linalg.norm(shapes.centres - before[0], axis=1)
            turn = np.einsum("sij,sij->s", shapes.frames[:, :3, :3], before[1])
            motion[:, 1] = np.arccos(np.clip(0.5 * (turn - 1.0), -1.0, 1.0))
        now = (
            (shapes.centres.copy(), shapes.frames[:, :3, :3].copy())
            if shapes is not None
            else None
        )
        whole = count % self.spec.whole_frame_every == 0
        clock = int(self._clock[0])
        self._kept[frame.camera] = (frame.view.copy(), kept, count + 1, now, clock)
        if whole:
            self.whole_frames += 1
        else:
            self.changed_frames += 1
        return kept, -1 if whole else last, motion

    def _pixels(self, frame: DepthFrame, t: float | None) -> PixelHistory:
        """The camera's pixel history, begun anew when the camera moved.

        Ranges along a pixel compare only from one pose. Cameras mounted on
        the robot keep none: their view changes with every motion of the arm,
        so they would hide space only while it stands still, right beside
        the hand (measured on ``cat_pushed_obstacle``, box pushed from the
        side at 5 cm/s, wall clock: 28-346 N with the wrist camera hiding,
        0-159 N without).
        """
        if t is None or self.spec.shadow_hold <= 0 or frame.camera in self._mounted:
            return _UNTRACKED
        kept = self._moved.get(frame.camera)
        if kept is not None and np.array_equal(kept[0], frame.view):
            return kept[1]
        shape = frame.depth.shape
        pixels = PixelHistory(
            np.full(shape, -np.inf), np.full(shape, -np.inf), np.zeros(shape)
        )
        self._moved[frame.camera] = (frame.view.copy(), pixels)
        return pixels

    def carve_robot(self, state: RobotState, shapes: WorldShapes | None = None) -> int:
        """Mark the unknown cells the robot holds free; return how many.

        ``shapes``: the robot's shapes placed at ``state``, when already at hand.

        With ``robot_space: held`` (the default), the first call frees the
        cells within the padded shapes and two cells more: a run starts clear
        of obstacles, and the contact query keeps the padded shapes a cell from
        obstacle cell centres (half a cell of inflation, half the cell's own
        size), so the arm starts a cell clear of the unknown space around it.
        Later calls free only the cells whose centre the padded shapes hold:
        the constraint keeps the arm farther than that from unknown cells, so in
        a run without contact they free nothing, and the robot never frees
        space it has not been in.

        With ``robot_space: nearby`` every call frees the padded shapes plus
        2 cm plus one cell (the space the self-filter took for the robot before it
        was measured from the shapes): unsafe, see :attr:`PerceptionSpec.robot_space`.
        """
        if self.geometry is None:
            return 0
        if self.spec.robot_space == "nearby":
            grow = self.geometry.padding + NEARBY_MARGIN + self.cell
        elif not self._started:
            grow = self.geometry.padding + 2.0 * self.cell
        else:
            grow = self.geometry.padding
        self._started = True
        if shapes is None:
            shapes = self.geometry.world_shapes(state)
        # Each grown shape's world box: its frame's box around the hull, rotated.
        R, t = shapes.frames[:, :3, :3], shapes.frames[:, :3, 3]
        centre = np.einsum("sij,sj->si", R, self._box_centres) + t
        half = np.einsum("sij,sj->si", np.abs(R), self._box_halves) + grow
        # Within the bounds: the layer of cells around them stays unknown.
        inner = self.lower + self.cell, self.upper - self.cell
        boxes = np.hstack(
            [np.maximum(centre - half, inner[0]), np.minimum(centre + half, inner[1])]
        )
        return int(
            carve_shapes(
                self.arrays,
                shapes.planes,
                shapes.plane_start,
                shapes.centres,
                shapes.radii,
                boxes,
                grow,
            )
        )

    def _see_through(
        self,
        frame: DepthFrame,
        readings: FrameArrays,
        limits: tuple[float, float, float],
        windows: np.ndarray,
        since: int,
        tiles: np.ndarray,
    ) -> int:
        """Free the cells in front of the readings (eroded over a cell's footprint).

        ``readings``: the frame as the passes read it; ``limits``: its
        :attr:`~DepthFrame.buffer_limits` (both taken once per frame);
        ``windows``: the parts of the image seen through (n, 4), pixel ranges
        [c0, c1) x [r0, r1), ``since`` and ``tiles``: the bricks seen through
        again (:func:`~cbp.perception.kernels.mark_seen`).
        """
        depth = readings.depth
        if not len(windows) and since < 0:
            return 0
        # The nearest reading around each pixel: a cell at a depth edge or on a
        # grazing surface spans several pixels, and is free only in front of all
        # of them. A pixel without a reading says nothing: it becomes -inf (NaN,
        # no return, leaves its neighbours be; eroded_ranges); background sees
        # to the far plane.
        h, w = depth.shape
        if len(windows) == 1 and tuple(windows[0]) == (0, w, 0, h):
            ranges = eroded_ranges(depth, frame.near, frame.far, *limits)
        else:
            ranges = eroded_ranges_in(depth, frame.near, frame.far, *limits, windows)
        box = self._frustum_box(frame)
        if box is None:
            return 0
        return int(
            mark_seen(
                self.arrays,
                box,
                ranges,
                frame.closest,
                self.spec.misses_to_clear,
                windows,
                since,
                tiles,
                readings,
            )
        )

    def _frustum_box(self, frame: DepthFrame) -> np.ndarray | None:
        """Index range of the grid cells within the frustum's bounding box."""
        reach = min(self.spec.max_range, frame.far / _min_axis_cos(frame))
        inv = frame.unprojection
        corners = [frame.position]
        for x in (-1.0, 1.0):
            for y in (-1.0, 1.0):
                p = inv.dot([x, y, 1.0, 1.0])
                far = p[:3] / p[3]
                ray = far - frame.position
                corners.append(frame.position + ray * (reach / np.linalg.norm(ray)))
        pts = np.array(corners)
        lo = np.floor((pts.min(axis=0) - self.lower) / self.cell).astype(int)
        hi = np.floor((pts.max(axis=0) - self.lower) / self.cell).astype(int) + 1
        lo = np.maximum(lo, 1)  # not the layer of cells around the bounds
        hi = np.minimum(hi, np.array(self.shape) - 1)
        if np.any(hi <= lo):
            return None
        return np.array([lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]], dtype=np.int64)

    # ------------------------------------------------------------------ snapshot

    def environment(self) -> OccupancyEnvironment:
        """A snapshot for the collision world: the obstacle shell, indexed by brick.

        Obstacles are the occupied cells and, with ``unknown: occupied``, the
        unknown ones. The snapshot owns its arrays: later frames do not change it.
        While no cell has changed state since the last snapshot, that snapshot
        is returned again (with what it has built on demand, such as the
        planners' octree), so its users can tell that the map has not changed.
        """
        if self._snapshot is not None and not self._dirty.any():
            return self._snapshot
        centres, start, slots = shell_update(
            self.arrays,
            self._blocked,
            self.spec.unknown_blocks,
            *self._shell,
        )
        self._shell = (centres, start, slots)
        self._snapshot = self.snapshot_of(
            centres, start, self._blocked.copy(), slots if len(slots) else None
        )
        return self._snapshot

    def snapshot_of(
        self,
        centres: FloatArray,
        start: np.ndarray,
        blocked: np.ndarray,
        slots: np.ndarray | None = None,
    ) -> OccupancyEnvironment:
        """The snapshot of a shell this grid's :meth:`environment` computed.

        Args:
            centres: the shell's cell centres (N, 3), brick by brick [m].
            start: brick b's cells are ``centres[start[b]:start[b + 1]]``.
            blocked: the obstacle mask (the grid's shape); the snapshot keeps it.
            slots: each brick's occupied places as bits, when the shell's
                pass gave them (None: computed from the centres).

        (A map updated in another process sends these three arrays; this
        grid's bounds and bricks index them.)
        """
        s = self.spec
        refiner = (
            MetaballRefiner(
                radius_cells=s.metaball_radius_cells,
                offset_cells=s.metaball_offset_cells,
            )
            if s.refine_normals
            else None
        )
        index = CellIndex.from_bricks(
            centres, start, self.lower, self.cell, self._brick, self._dims, slots
        )
        return OccupancyEnvironment(
            centres,
            self.cell,
            refiner,
            index=index,
            blocked=BlockedGrid(
                blocked, self.lower.copy(), self.cell, outside=s.unknown_blocks
            ),
        )

    @property
    def bricks(self) -> tuple[int, tuple[int, ...]]:
        """Cells per brick side, and bricks along x, y and z (the snapshot's)."""
        return self._brick, tuple(int(n) for n in self._dims)

    def __repr__(self) -> str:
        """Size, resolution and the cells in each state."""
        return (
            f"OccupancyGrid(shape={self.shape}, cell={self.cell}, "
            f"occupied={self.count(OCCUPIED)}, unknown={self.count(UNKNOWN)}, "
            f"frames={self.frames})"
        )


def _min_axis_cos(frame: DepthFrame) -> float:
    """The cosine of the widest angle between the optical axis and a corner ray."""
    inv = frame.unprojection
    centre = inv.dot([0.0, 0.0, 1.0, 1.0])
    axis = centre[:3] / centre[3] - frame.position
    axis /= np.linalg.norm(axis)
    p = inv.dot([1.0, 1.0, 1.0, 1.0])
    ray = p[:3] / p[3] - frame.position
    return float(axis.dot(ray) / np.linalg.norm(ray))
