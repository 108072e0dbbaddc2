# SPDX-License-Identifier: Apache-2.0
"""The ``perception:`` section of a scenario: where the world model comes from."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from cbp.errors import ConfigError, require_between
from cbp.robot import FloatArray
from cbp.spatial import Pose

Vec3 = tuple[float, float, float]

MAX_CELLS = 1 << 27
"""The largest map: three bytes a cell, so about 400 MB."""

DEFAULT_BOUNDS: tuple[Vec3, Vec3] = ((-1.0, -1.0, -0.1), (1.5, 1.0, 1.5))
"""The region mapped when no bounds are given and no reach bounds the robot
(a base that moves) [m]."""


@dataclass(frozen=True, kw_only=True)
class DepthNoise:
    """How a depth camera's readings err: noise, edges without readings, dropout.

    Simulated cameras apply it to every frame they render
    (:mod:`cbp.sim.depth_noise`), and the map allows for it: the robot filter
    (``perception.robot_margin``) grows by ``map_sigmas`` times :meth:`sigma`
    at each reading's depth, and so does the hidden-space rule's gap. The
    defaults are a structured-light sensor of the Kinect kind: the axial
    standard deviation measured by Nguyen et al. (2012),
    sigma(z) = 0.0012 + 0.0019 (z - 0.4)^2 m, about 1.3 mm at 0.5 m, 3.5 mm
    at 1.5 m and 6 mm at 2.2 m.
    """

    enabled: bool = True
    """Apply the model (False: frames exactly as rendered, and the robot
    filter's margin as set)."""
    sigma_0: float = 0.0012
    """Axial noise's standard deviation at ``z0`` [m]: sigma(z) = sigma_0 +
    sigma_growth (z - z0)^2, z the depth along the optical axis."""
    sigma_growth: float = 0.0019
    """How fast sigma grows away from ``z0`` [1/m]."""
    z0: float = 0.4
    """The depth where sigma is least [m]."""
    edge_jump: float = 0.0
    """A pixel whose depth is more than this beyond one of its four
    neighbours' gives no reading [m]: the far side of a depth edge, where real
    sensors lose the pattern or mix the two surfaces (0.03 is a fair value).
    0 (the default): edges kept. Off by default because the map does not yet
    cope with it for obstacles that move: on ``cat_pushed_obstacle`` with the
    cameras (virtual clock), 0.03 let the box press the arm with 248 N (0 N
    with edges kept), the band lost beside the arm's silhouette hiding the
    box's leading face; the eight CAT paper scenes kept 0 N and their reach
    with it (``docs/noise.md``)."""
    dropout: float = 0.002
    """The fraction of the other pixels that give no reading, at random."""
    seed: int = 0
    """The random stream's seed; each camera draws from its own stream (the
    seed and the camera's name), so a run is reproducible."""
    map_sigmas: float = 3.0
    """How many sigmas of a reading's depth the map allows for: the robot
    filter grows by this many (a reading of the robot is spread along its ray
    by the noise), and the gap beyond which a nearer reading hides the space
    behind it by sqrt(2) times as many (two readings of a still surface)."""

    def __post_init__(self) -> None:
        """Non-negative sizes; a fraction in [0, 1)."""
        for name in ("sigma_0", "sigma_growth", "z0", "edge_jump", "map_sigmas"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0.0 <= value <= 10.0):
                raise ConfigError(f"must be in [0, 10], got {value}", name)
        if not 0.0 <= self.dropout < 1.0:
            raise ConfigError(f"must be in [0, 1), got {self.dropout}", "dropout")
        if not 0 <= self.seed < 2**63:
            raise ConfigError(f"must be in [0, 2^63), got {self.seed}", "seed")

    def sigma(self, z: FloatArray | float) -> FloatArray:
        """The axial noise's standard deviation at depth ``z`` [m] (0 when off)."""
        if not self.enabled:
            return np.zeros_like(np.asarray(z, dtype=float))
        z = np.asarray(z, dtype=float)
        return np.asarray(self.sigma_0 + self.sigma_growth * (z - self.z0) ** 2)


@dataclass(frozen=True, kw_only=True)
class CameraSpec:
    """A depth camera: fixed in the world, or mounted on a robot link.

    A fixed camera looks at ``target`` from ``position``. A mounted camera
    (``parent:`` a frame of the robot) sits at ``offset`` in that frame and looks
    along the offset's +z axis with +x to the right of the image and +y down
    (the optical frame of ROS and OpenCV); its pose follows the robot.
    """

    name: str = ""
    """Name in events and plots (default: ``camera<i>`` in list order)."""
    position: Vec3 | None = None
    """Optical centre in the world [m] (fixed cameras)."""
    target: Vec3 | None = None
    """A point on the optical axis [m] (fixed cameras)."""
    up: Vec3 = (0.0, 0.0, 1.0)
    """The world direction that appears up in the image (fixed cameras)."""
    parent: str | None = None
    """The robot frame a mounted camera is fixed to (for example ``panda_hand``;
    ``end_effector``: the robot's end effector); None for a fixed camera."""
    offset: Pose = field(default_factory=lambda: Pose(position=(0.0, 0.0, 0.0)))
    """The optical frame in ``parent``'s frame (mounted cameras)."""
    width: int = 320
    """Image width [px]."""
    height: int = 240
    """Image height [px]."""
    fov_deg: float = 60.0
    """Vertical field of view [deg]."""
    near: float = 0.1
    """Minimum range [m]: nearer surfaces give no reading (never a view past
    them, as a renderer's clipping plane would)."""
    far: float = 3.0
    """Far clipping distance [m]; farther surfaces are not seen."""
    rate_hz: float = 15.0
    """Frames per second."""
    renderer: Literal["tiny", "raycast", "opengl"] = "raycast"
    """How a simulated camera renders: ``raycast``, a compiled ray cast against
    the scene's shapes (:mod:`cbp.sim.raycast` on PyBullet,
    :mod:`cbp.sim.mujoco.raycast` on MuJoCo: 1-2 ms a frame); ``tiny``,
    PyBullet's tiny renderer (PyBullet only: 10-35 ms a frame, in the control
    loop's process); ``opengl``, MuJoCo's OpenGL renderer (MuJoCo only, through
    EGL: about twice the ray cast's time here, without a GPU). The pixels
    agree within 1 mm but on silhouette edges; the ray cast sees spheres and
    cylinders as they are, not as facets. A real camera ignores it."""
    body: Vec3 | None = (0.04, 0.04, 0.025)
    """A mounted camera's housing [m]: a box (width, height, depth) along the
    optical frame's x, y and z, its front face at the optical centre. It joins
    the robot's collision shapes while the cameras are in use, so the camera is
    kept out of obstacles like any link (a camera inside a board would see
    through it and empty the board's cells). None: no housing (then nothing
    keeps the optical centre out of obstacles). Fixed cameras ignore it."""
    noise: DepthNoise = field(default_factory=DepthNoise)
    """How the camera's readings err (:class:`DepthNoise`); on by default.
    ``noise: {enabled: false}``: frames exactly as rendered."""

    def __post_init__(self) -> None:
        """Positive sizes, a sensible frustum, and either a pose or a parent."""
        if self.body is not None and not all(0.0 < v < 1.0 for v in self.body):
            raise ConfigError(
                f"each side must be within (0, 1) m, got {list(self.body)}", "body"
            )
        if self.width < 8 or self.height < 8:
            raise ConfigError(
                f"image must be at least 8x8, got {self.width}x{self.height}", "width"
            )
        if self.width * self.height > 4096 * 4096:
            raise ConfigError(
                f"image of {self.width}x{self.height} px is too large", "width"
            )
        if not 1.0 < self.fov_deg < 170.0:
            raise ConfigError(f"must be in (1, 170) deg, got {self.fov_deg}", "fov_deg")
        if not 0 < self.near < self.far < 1e3:
            raise ConfigError(
                f"need 0 < near < far < 1000 m, got near={self.near}, far={self.far}",
                "near",
            )
        if not 0 < self.rate_hz <= 1000.0:
            raise ConfigError(f"must be in (0, 1000] Hz, got {self.rate_hz}", "rate_hz")
        if self.parent is None:
            if self.position is None or self.target is None:
                raise ConfigError(
                    "a fixed camera needs 'position' and 'target' (or give "
                    "'parent', a robot frame, for a mounted camera)",
                    "position" if self.position is None else "target",
                )
            if not np.all(np.isfinite(self.position + self.target + self.up)):
                raise ConfigError("must be finite", "position")
            axis = np.subtract(self.target, self.position)
            if not np.linalg.norm(axis) > 1e-9:
                raise ConfigError("position and target coincide", "target")
            if np.linalg.norm(np.cross(axis, self.up)) < 1e-9 * np.linalg.norm(axis):
                raise ConfigError(
                    "'up' is parallel to the optical axis (target - position)", "up"
                )
        elif self.position is not None or self.target is not None:
            raise ConfigError(
                "a mounted camera (with 'parent') takes 'offset', not "
                "'position'/'target'",
                "position" if self.position is not None else "target",
            )


@dataclass(frozen=True, kw_only=True)
class PerceptionSpec:
    """Where the collision world's environment comes from."""

    source: Literal["ground_truth", "depth_camera"] = "ground_truth"
    """``ground_truth``: the declared objects; ``depth_camera``: an occupancy map
    built at run time from the cameras' depth images."""
    cameras: list[CameraSpec] = field(default_factory=list)
    """The cameras feeding the one map (``depth_camera`` needs at least one)."""
    camera: CameraSpec | None = None
    """One camera: shorthand for a one-item ``cameras`` list."""
    unknown: Literal["occupied", "free"] = "occupied"
    """How the map counts the space no camera has seen (and the robot has not
    held): ``occupied`` (an obstacle, for every collision-aware method) or
    ``free`` (the behaviour before unknown space was tracked, for
    comparison)."""
    cell_size: float = 0.01
    """Occupancy map resolution [m]."""
    bounds: tuple[Vec3, Vec3] | None = None
    """Lower and upper corners of the mapped region [m]. Space outside it is
    unknown (an obstacle with ``unknown: occupied``): the map holds a layer of
    unknown cells around it that no camera sees through and the robot never
    frees, and a camera that sees surfaces outside it within the arm's reach
    says so in an event. None (the default): the box the padded robot can
    ever reach (every shape's bounding sphere about the reach of its centre,
    :func:`~cbp.scenario.reach.reach_box`: for the Panda on its base, 2.0 x
    2.0 x 2.0 m, 8 M cells at 1 cm); :data:`DEFAULT_BOUNDS` for a robot whose
    base moves. Give smaller bounds to make the map cheaper where the scene
    confines the arm (``configs/cat.yaml``: the table's side of the arm)."""
    max_range: float = 2.5
    """Depth readings farther than this are ignored [m]."""
    misses_to_clear: int = 2
    """Frames that must see through a cell before it is cleared."""
    whole_frame_every: int = 15
    """A camera's frames taken from where its last one was (a fixed camera's, a
    mounted one's while the arm stands) are integrated only where they changed:
    the pixels whose reading differs from the one last integrated by more than
    two readings of a still surface differ (``map_sigmas`` sigmas of the
    camera's noise times sqrt(2); with no noise, at all), the space seen
    through only over the image's tiles holding one. An unchanged reading only
    keeps its cell occupied, as the same reading would. Every this many frames
    of a camera, and its first from a new pose, are integrated whole; 1: every
    frame whole (the map as before; slower: a still scene's frames add nothing).
    Skipping the space seen through along unchanged pixels can only leave cells
    blocked that a whole frame would free, for at most this many frames."""
    robot_margin: float = 0.005
    """Depth readings within this distance of the robot's shapes are taken for
    the robot and dropped [m]. Measured from the shapes themselves (not the
    padded ones), each grown by how far its link's visual geometry reaches past
    it (:attr:`~cbp.collision.geometry.RobotGeometry.visual_excess`): the margin
    covers the error between the robot's modelled and actual pose; each
    camera's depth noise adds ``noise.map_sigmas`` times its sigma at the
    reading's depth (:class:`DepthNoise`; 3 x 3.5 mm at 1.5 m). Every
    reading farther out is mapped, even inside the padding, so an
    obstacle that comes at the arm stays in view until it is this close (a
    reading the filter drops leaves its cell as it was). Before it was
    measured from the shapes it was 0.02 beyond the padded shapes: an obstacle
    pushed into the arm vanished 3 cm before it touched."""
    robot_space: Literal["held", "nearby"] = "held"
    """Which unseen space the robot's presence frees. ``held`` (the default): at
    the first frame its padded shapes and two cells more (a run starts clear of
    obstacles, as the loader checks for declared ones), after that only the
    cells its padded shapes hold, so it never frees space it has not been in.
    ``nearby`` (the behaviour before ``held``): on every frame the padded shapes plus
    2 cm plus one cell. That lets the arm move beside space no
    camera sees (its own shadow) and is unsafe: each frame frees centimetres
    beyond where the arm may stand, so it can walk into an obstacle nothing has
    seen."""
    min_valid_fraction: float = 0.2
    """A depth frame with fewer pixels holding a reading than this fraction is
    dropped (an event): all-NaN, all-zero or blinded frames never reach the
    map."""
    camera_timeout: float = 0.5
    """A camera that gives no valid frame for this long stops the robot (it
    holds until valid frames come again) [s]."""
    max_far_fraction: float = 0.99
    """A frame that reads nothing up to its far plane in at least this
    fraction of its pixels is not believed (a blinded or failed sensor would
    clear the map); 1: never refused for that."""
    see_through_fraction: float = 0.5
    """A fixed camera's frame is not believed when more than this fraction of
    the robot's joints in its view read farther away than the joint (the
    camera moved, or its pose is wrong); 1: never refused for that."""
    see_through_tolerance: float = 0.05
    """How much farther than a joint a pixel must read to see through it [m]."""
    motion_window: float = 1.0
    """Estimate how fast the mapped obstacles come at each robot shape over
    this window [s], and plan against them that much nearer, as declared
    objects that move are (with ``collision.predict_motion``, the default;
    :class:`~cbp.perception.motion.ApproachEstimator`). 0: off, the map has no
    velocities. In scenes where nothing moves the estimate stays 0 (unseen
    space is an obstacle: cells turn into obstacles near the arm only when
    something enters space seen free). Measured on ``cat_pushed_obstacle``
    in wall-clock runs, six each, with ``shadow_hold`` (the wrist camera
    hiding space too, as it did then; it no longer does): a box lowered onto
    the arm at 5 cm/s pressed it with 0-399 N with 1 s and 0.3-24 kN with
    0.5 s; pushed from the side at 5 cm/s 28-346 N (1 s) and 0-58 N (0.5 s),
    at 10 cm/s 173-245 N (1 s) and 91-171 N (0.5 s). In virtual time (the map
    integrates each frame at once) 0.5 s did better on all of them: virtual
    time does not stand for a run beside a map thread here."""
    cluster_motion: bool = False
    """Also measure the mapped obstacles' velocities cluster by cluster
    (touching occupied cells within 0.3 m of the robot, followed from
    snapshot to snapshot over ``motion_window``;
    :class:`~cbp.perception.motion.ClusterMotion`), and add to each snapshot
    the cells a moving cluster passes over the look-ahead [s] (and, with
    ``map_process``, the snapshot's age [s]). A moving obstacle is then
    measured on its own, not hidden by a nearer static one as in the per-shape
    approach estimate (which stays on). Needs ``motion_window`` > 0 and
    ``collision.predict_motion``."""
    moving_speed: float = 0.25
    """How fast an obstacle the cameras see moving is assumed to come [m/s].
    Cells something entered (space a fixed camera saw free, now behind a
    nearer reading) within ``shadow_hold`` are measured this speed times the
    look-ahead (and the snapshot's age) nearer, in every direction
    (:mod:`cbp.perception.moving`): the arm keeps the separation it needs to
    get away from an obstacle at that speed, as speed and separation
    monitoring counts it. Once no cell has been entered for a while, the
    look-ahead is measured at the speed that could have gone unseen (a cell
    per that while), and at least this speed over a fixed camera's frame
    period and the snapshot's age
    (:func:`~cbp.perception.moving.moving_growth`). Set it to the fastest
    obstacle the robot must outrun;
    an obstacle faster than the arm can retreat is reported as it comes
    (``docs/moving_scenes.md``). 0: moving cells are measured where they are."""
    shadow_hold: float = 1.0
    """Space a fixed camera saw free and now sees hidden behind a nearer
    surface (something came between: an obstacle moved in) is unknown again,
    from that surface to two cells beyond the robot's padded shapes (where the
    contact rows would not push the arm out of it), while the surface moves and
    this long after it stops [s]; then, as any shadow, it keeps the state it
    was last seen in. Without it an obstacle that comes at the arm is mapped by
    the faces the cameras see, and the rest of it moves into space the map
    still holds free (a box lowered onto the arm: 8.5 kN). Cameras mounted
    on the robot keep no such history (their view moves with the arm). 0:
    off."""
    map_process: bool = True
    """In wall-clock runs (``timing.clock: wall``), integrate the frames in a
    process of its own (:class:`~cbp.perception.map_process.ProcessMapUpdater`:
    frames and snapshots through shared memory, each snapshot stamped with the
    capture time of its newest frame [s], approaching obstacles measured ahead
    over the look-ahead plus the snapshot's age [s]) rather than in a thread
    beside the control loop, which shares the interpreter lock with it (false).
    Virtual-time runs integrate each frame in the loop either way. A map
    process that ends, or a map more than ``camera_timeout`` [s] behind the
    newest frame, stops the robot (an event). Measured with
    ``benchmarks/map_latency.py`` (``cat_pushed_obstacle``: a box pushed from
    the side at 5 and 10 cm/s and lowered at 5 cm/s, two runs each, load
    average 1.6-3.7 on the shared 2-core machine): capture to use in simulated
    time, median 25-39 ms (p95 48-114 ms) in the process against 33-114 ms
    (66-198 ms) in the thread (virtual time 0-27 ms); integration 6.5-14 ms a
    frame against 13-39 ms; the loop's QP steps per period 39-123 against
    30-69; peak forces 0-173 N against 0-707 N (0 N in virtual time). Under a
    load average of 6 (and frames still sent by a queue) neither was better."""
    virtual_latency: float = 0.0
    """In virtual-time runs, install each map snapshot this long after the
    capture of its newest frame [s], and measure it ahead over that age, as a
    map in its own process is in wall-clock runs (capture to use: see
    ``map_process``); 0: at once, as virtual time always did. A run that is
    safe only with a map that never lags is not safe beside a real one: with
    snapshots 67 ms late, the generated scene moving_3 pressed the arm with
    39 kN where it stayed at 0 N without the delay, until unseen space was
    read from the newest map (:mod:`cbp.perception.moving`)."""
    refine_normals: bool = True
    """Re-estimate contact normals from a metaball surface (CAT Sec. IV-B)."""
    metaball_radius_cells: float = 3.0
    """Metaball kernel radius, in cells."""
    metaball_offset_cells: float = 0.5
    """Metaball evaluation point, in cells outside the obstacle witness point."""

    def __post_init__(self) -> None:
        """Camera present for depth_camera; positive sizes; ordered bounds."""
        if self.camera is not None and self.cameras:
            raise ConfigError(
                "give either 'camera' (one) or 'cameras' (a list), not both", "camera"
            )
        if self.source == "depth_camera" and not self.all_cameras:
            raise ConfigError(
                "source 'depth_camera' needs 'cameras:' (or one 'camera:')", "cameras"
            )
        names = [c.name for c in self.all_cameras]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise ConfigError(
                f"camera names must be unique; repeated: {', '.join(repeated)}",
                "cameras",
            )
        require_between(self, 0.0, 10.0, "m/s", "moving_speed")
        require_between(self, 0.0, 10.0, "s", "virtual_latency")
        require_between(self, 0.0, 60.0, "s", "shadow_hold")
        require_between(self, 0.0, 10.0, "s", "motion_window")
        for name in ("max_far_fraction", "see_through_fraction"):
            if not 0.0 < getattr(self, name) <= 1.0:
                raise ConfigError(f"must be in (0, 1], got {getattr(self, name)}", name)
        if not 0.0 < self.see_through_tolerance <= 1.0:
            raise ConfigError(
                f"must be in (0, 1] m, got {self.see_through_tolerance}",
                "see_through_tolerance",
            )
        if not 0.0 <= self.min_valid_fraction <= 1.0:
            raise ConfigError(
                f"must be in [0, 1], got {self.min_valid_fraction}",
                "min_valid_fraction",
            )
        slowest = min((c.rate_hz for c in self.all_cameras), default=1e3)
        if not 1.0 / slowest < self.camera_timeout <= 60.0:
            raise ConfigError(
                f"must be longer than the slowest camera's frame period "
                f"({1.0 / slowest:g} s) and at most 60 s, got {self.camera_timeout}",
                "camera_timeout",
            )
        if not 0.001 <= self.cell_size <= 0.2:
            raise ConfigError(
                f"must be in [0.001, 0.2] m, got {self.cell_size}", "cell_size"
            )
        if self.bounds is not None:
            lo, hi = self.bounds
            if not all(a < b for a, b in zip(lo, hi, strict=True)):
                raise ConfigError(
                    f"lower corner must be below upper, got {lo}, {hi}", "bounds"
                )
            cells = np.prod(np.ceil((np.subtract(hi, lo)) / self.cell_size) + 2)
            if cells > MAX_CELLS:
                raise ConfigError(
                    f"the map would have {cells:.3g} cells (bounds / cell_size); "
                    f"at most {MAX_CELLS:.3g}: shrink the bounds or grow the cells",
                    "bounds",
                )
        if not 1 <= self.whole_frame_every <= 1000:
            raise ConfigError(
                f"must be in [1, 1000], got {self.whole_frame_every}",
                "whole_frame_every",
            )
        if not 1 <= self.misses_to_clear <= 1000:
            raise ConfigError(
                f"must be in [1, 1000], got {self.misses_to_clear}", "misses_to_clear"
            )
        if not 0.0 <= self.robot_margin <= 0.2:
            raise ConfigError(
                f"must be in [0, 0.2] m, got {self.robot_margin} (below 0 the "
                "robot's own readings would be mapped as obstacles beside it)",
                "robot_margin",
            )

    @property
    def all_cameras(self) -> list[CameraSpec]:
        """``cameras``, or ``camera`` as a list; unnamed ones named ``camera<i>``."""
        cameras = self.cameras or ([self.camera] if self.camera is not None else [])
        return [
            c if c.name else replace(c, name=f"camera{i}")
            for i, c in enumerate(cameras)
        ]

    @property
    def region(self) -> tuple[Vec3, Vec3]:
        """The mapped region: ``bounds``, or :data:`DEFAULT_BOUNDS` when None.

        A run resolves None to the box about the arm's reach first
        (:meth:`with_bounds`); a grid built from a spec it did not resolve
        maps the default box.
        """
        return self.bounds if self.bounds is not None else DEFAULT_BOUNDS

    def with_bounds(self, lower: FloatArray, upper: FloatArray) -> PerceptionSpec:
        """This spec mapping the box from ``lower`` to ``upper`` [m], checked.

        Raises ConfigError (``bounds``) when the box would hold too many cells.
        """
        lo = (float(lower[0]), float(lower[1]), float(lower[2]))
        hi = (float(upper[0]), float(upper[1]), float(upper[2]))
        return replace(self, bounds=(lo, hi))

    @property
    def unknown_blocks(self) -> bool:
        """Whether unknown space counts as an obstacle."""
        return self.unknown == "occupied"
