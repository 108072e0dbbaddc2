# SPDX-License-Identifier: Apache-2.0
"""Settings of every method, as written under ``method.<name>:`` in a scenario.

Plain data: the executors that run them live in :mod:`cbp.executors`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

from cbp.errors import ConfigError, require, require_between

if TYPE_CHECKING:
    from cbp.robot import FloatArray, RobotModel

__all__ = [
    "CatSettings",
    "ClockKind",
    "ExecutorTiming",
    "HybridSettings",
    "IkSearchSettings",
    "IkSettings",
    "JtSettings",
    "KinematicSettings",
    "LookSettings",
    "MpSettings",
    "PlannerSettings",
    "VelocitySettings",
    "VirtualCosts",
    "Work",
]


#: How a planning budget is counted.
ClockKind = Literal["wall", "virtual"]
#: The kinds of work a planner charges.
Work = Literal[
    "qp_step", "ik_iteration", "collision_check", "map_check", "trajectory_point"
]


@dataclass(frozen=True, kw_only=True)
class VirtualCosts:
    """The ``timing.virtual_costs:`` section: seconds charged per unit of work."""

    qp_step: float = 145e-6
    """One CAT step: the engine's QP, integration and step validation [s]."""
    ik_iteration: float = 26e-6
    """One damped-least-squares iteration of the IK search [s]. Since the
    step is compiled an iteration costs about 9 us (300 Panda solves): this
    charge is on the safe side, and kept while the looks' outcomes on the
    virtual clock shift with it (the hybrid behind the wall took 15 looks at
    9 us, 10 at 26)."""
    collision_check: float = 11e-6
    """One yes-or-no collision check of a configuration against declared
    objects (IK, MP) [s]."""
    map_check: float = 60e-6
    """The same check against an occupancy map [s] (compiled: 18-89 us of CPU
    measured in the paper's scenes with the cameras, by how near the
    configurations are to the map's cells; 46-57 us on average along MP's
    runs: ``docs/comparison.md``)."""
    trajectory_point: float = 4e-6
    """Timing one path point of the spliced trajectory [s]."""

    def __post_init__(self) -> None:
        """Positive costs."""
        require(self, "> 0", "qp_step", "ik_iteration", "collision_check")
        require(self, "> 0", "map_check", "trajectory_point")


#: Shortest and longest control step or tick an executor accepts [s].
MIN_DT, MAX_DT = 1e-4, 1.0


@dataclass(frozen=True, kw_only=True)
class ExecutorTiming:
    """Command period, time budget and trajectory limits of a trajectory executor."""

    period: float = 1.0 / 30.0
    """Nominal command period [s] (the paper: 30 Hz for CAT and IK, 4 Hz for MP)."""
    min_period: float | None = None
    """Shortest adaptive period [s] (default: the nominal period)."""
    max_period: float | None = None
    """Longest adaptive period [s] (default: 4x the nominal period)."""
    growth: float = 1.5
    """The period is multiplied by this after a missed deadline."""
    shrink: float = 0.9
    """... and by this after a period that used less than half its time."""
    time_budget: float = 0.8
    """Fraction of the period the planner may use (the rest is margin)."""
    velocity_scale: float = 0.5
    """Trajectories use this fraction of the robot's velocity limits."""
    acceleration_scale: float = 0.5
    """... and this fraction of its acceleration limits."""
    clock: ClockKind = "wall"
    """How the budget is counted: ``wall`` (wall-clock time, as on a robot) or
    ``virtual`` (counted work at ``virtual_costs``: the same results on any
    machine and load, faster than real time; :mod:`cbp.run.budget`)."""
    virtual_costs: VirtualCosts = field(default_factory=VirtualCosts)
    """Seconds charged per unit of work when ``clock`` is ``virtual``."""

    def __post_init__(self) -> None:
        """Positive times, sensible factors."""
        require_between(self, 1e-3, 10.0, "s", "period")
        lo, hi = self.bounds()
        if hi > 60.0:
            raise ConfigError(f"must be at most 60 s, got {hi}", "max_period")
        if not 0 < lo <= self.period <= hi:
            raise ConfigError(
                f"need 0 < min_period <= period <= max_period, got {lo}, "
                f"{self.period}, {hi}",
                "min_period",
            )
        if not self.growth >= 1:
            raise ConfigError(f"must be >= 1, got {self.growth}", "growth")
        if not 0 < self.shrink <= 1:
            raise ConfigError(f"must be in (0, 1], got {self.shrink}", "shrink")
        for name in ("time_budget", "velocity_scale", "acceleration_scale"):
            if not 0 < getattr(self, name) <= 1:
                raise ConfigError(f"must be in (0, 1], got {getattr(self, name)}", name)

    def limits(self, robot: RobotModel) -> tuple[FloatArray, FloatArray]:
        """The robot's velocity and acceleration limits as trajectories use them.

        Each scaled by ``velocity_scale`` and ``acceleration_scale``.
        """
        return (
            robot.velocity_limits * self.velocity_scale,
            robot.acceleration_limits * self.acceleration_scale,
        )

    def bounds(self) -> tuple[float, float]:
        """Shortest and longest period [s]."""
        lo = self.min_period if self.min_period is not None else self.period
        hi = self.max_period if self.max_period is not None else 4.0 * self.period
        return lo, hi


@dataclass(frozen=True, kw_only=True)
class KinematicSettings:
    """The ``method.kinematic:`` section: QP steps integrated exactly."""

    dt: float = 0.01
    """Duration of one control step [s]."""

    def __post_init__(self) -> None:
        """A step between 0.1 ms and 1 s."""
        require_between(self, MIN_DT, MAX_DT, "s", "dt")


@dataclass(frozen=True, kw_only=True)
class CatSettings:
    """The ``method.cat:`` section."""

    timing: ExecutorTiming = field(default_factory=ExecutorTiming)
    """Command period, budget and trajectory limits."""
    step_dt: float = 0.01
    """Duration the engine assigns to one QP step [s]: the ``joint_velocity``
    constraint bounds each step by v_max * step_dt."""
    max_step_stretch: float = 2.0
    """When fewer steps fit in the period's budget than its path needs at
    ``step_dt`` (a loaded machine, an arm pressed by obstacles), each step
    covers up to this many times ``step_dt``, so the path still reaches over
    the command period and the arm keeps its speed: a path shorter than the
    period stops the arm at its end. 1: off. Measured on a generated scene
    with moving obstacles, on the wall clock of a loaded 2-core machine: 1-3
    steps fitted a period, and the arm, held to 60 % of its speed and less,
    was caught (228-268 N; docs/moving_scenes.md). The step guard validates
    each step as before; a step of twice 20 ms at half the Panda's velocity
    limits moves a link at most about 4 cm, within CAT's 5 cm activation
    distance."""
    max_steps: int = 2000
    """At most this many QP steps per period (the time budget usually ends it)."""
    converged_step: float = 5e-5
    """A step whose largest joint change is below this [rad] counts as still;
    three in a row end the period's computation (time was spare). An arm
    held by a board crept on for a hundred steps of 1-3e-5 rad a period at
    1e-5; at 5e-5 the paper's scenes reach their goals within 15 ms of the
    time they did, with a third of the steps (docs/cat_scenes.md)."""
    max_rejections: int = 3
    """Consecutive rejected steps that end the period's path."""
    reach_periods: float = 4.0
    """The path is long enough, and the period's computation ends, once some
    joint travels along it as far as it could at the timing's velocity limit
    over this many command periods and then brake to a stop: the next
    period's plan replaces the path long before the arm could follow it
    further. 0: steps until the budget is spent or the motion converges (the
    CAT paper). At 2 a free reach took 30 ms longer (the path is timed to
    stop at its end); at 4 the paper's scenes move as at 0. The hybrid's CAT
    always steps until its budget is spent: its stall detector reads the end
    of the path, which must run into the local minimum."""

    def __post_init__(self) -> None:
        """Positive values."""
        require_between(self, 0.0, 100.0, "periods", "reach_periods")
        require_between(self, MIN_DT, MAX_DT, "s", "step_dt")
        require_between(self, 1, 100_000, "steps", "max_steps")
        require_between(self, 1.0, 10.0, "", "max_step_stretch")
        require_between(self, 1, 1000, "steps", "max_rejections")
        require(self, ">= 0", "converged_step")


@dataclass(frozen=True, kw_only=True)
class IkSearchSettings:
    """How collision-free inverse kinematics is searched (IK and MP methods)."""

    redundant_joint: str | None = None
    """Joint swept when the nearest solution collides (the PR2's IK swept its
    redundant joint); default: the third joint of the arm (the upper-arm roll on
    a 7-DOF arm)."""
    sweep_step: float = 0.2
    """Spacing of the redundant joint's values, tried nearest first [rad]."""
    random_starts: int = 32
    """Starts drawn at random within the joint limits, tried after the sweep.
    From a configuration the arm reached by looking about, every start of the
    sweep may end at a joint limit while random ones converge: behind the wall
    of ``cat_local_minimum``, 0 of the sweep's 29 starts converged and 8 of 30
    random ones, 1 of them free of the seen obstacles."""
    max_iterations: int = 80
    """Damped least-squares iterations per solve."""
    stall_iterations: int = 20
    """A solve whose pose error has not fallen by a thousandth over this many
    iterations is given up (0: never): held at a joint limit or in a
    singularity, it would spend its remaining iterations there. Measured on
    640 solves of the Panda: a third of the iterations, the same solutions
    in 639."""
    position_tolerance: float = 1e-3
    """A solution is within this of the goal position [m] ..."""
    rotation_tolerance: float = 1e-2
    """... and this rotation [rad]."""
    limit_margin: float = 0.02
    """Solutions keep this far inside the joint limits [rad]."""

    def __post_init__(self) -> None:
        """Positive values."""
        require(
            self,
            "> 0",
            "sweep_step",
            "position_tolerance",
            "rotation_tolerance",
        )
        require_between(self, 1, 10_000, "iterations", "max_iterations")
        require_between(self, 0, 10_000, "iterations", "stall_iterations")
        require_between(self, 0, 10_000, "starts", "random_starts")


@dataclass(frozen=True, kw_only=True)
class IkSettings:
    """The ``method.ik:`` section: collision-aware IK + joint interpolation."""

    timing: ExecutorTiming = field(default_factory=ExecutorTiming)
    """Command period (30 Hz, as CAT), budget and trajectory limits."""
    search: IkSearchSettings = field(default_factory=IkSearchSettings)
    """The IK search."""
    interpolation_step: float = 0.02
    """Largest joint change between two collision-checked configurations [rad];
    they are closer where the links would otherwise sweep more than the padding
    between them (:mod:`cbp.collision.motion`)."""

    def __post_init__(self) -> None:
        """Positive step."""
        require(self, "> 0", "interpolation_step")


@dataclass(frozen=True, kw_only=True)
class LookSettings:
    """The planners' ``look:`` section: turn the arm's camera to an unseen goal.

    With the cameras and ``perception.unknown: occupied``, a goal in space no
    camera has seen has no configuration the planners accept. When the IK
    search finds none and at least ``unseen_share`` of the cube of ``radius``
    about the goal is unseen, the planner says so and (with a camera mounted
    on the arm) plans to a configuration from which that camera sees the
    goal, holds there until the map has taken ``frames`` of that camera's frames
    captured at the view (``dwell`` at the most), and searches again
    (:mod:`cbp.executors.look`).
    """

    enabled: bool = True
    """Turn the camera (false: only say that the goal is unseen)."""
    camera: str | None = None
    """The camera to turn; default: the first camera mounted on the robot."""
    spread: float = 0.6
    """Views are sampled with each joint moved by up to this from the arm's
    configuration [rad] (near it, the arm stays in space already seen)."""
    radius: float = 0.05
    """Half the side of the cube about the goal's position measured [m]."""
    unseen_share: float = 0.25
    """Look when at least this share of the cube is unseen."""
    frames: int = 2
    """Frames of the camera, captured at the view, that the map takes in
    before the search goes on (more fill the holes of depth dropouts)."""
    dwell: float = 0.4
    """The longest the arm holds at the view waiting for them [s] (a camera
    whose frames are dropped, or a map that lags, ends the hold then)."""
    looks: int = 16
    """Looks per goal at most (tries that find no view count). Behind the
    wall of ``cat_local_minimum`` the hybrid needed 6 to 13 (about a second
    each) before the goal and the way to it were seen."""

    def __post_init__(self) -> None:
        """Positive distances and times, a share in (0, 1]."""
        require(self, "in (0, 1]", "unseen_share")
        require_between(self, 0.01, 3.2, "rad", "spread")
        require_between(self, 0.005, 0.5, "m", "radius")
        require_between(self, 0.0, 10.0, "s", "dwell")
        require_between(self, 1, 100, "looks", "looks")
        require_between(self, 1, 100, "frames", "frames")


@dataclass(frozen=True, kw_only=True)
class PlannerSettings:
    """A global planner: IK for the goal, OMPL RRT-Connect to it (MP, hybrid)."""

    search: IkSearchSettings = field(default_factory=IkSearchSettings)
    """The IK search for the goal configuration."""
    simplify_fraction: float = 0.3
    """Share of the planning budget left for path simplification."""
    simplify: Literal["shortcut", "full"] = "shortcut"
    """``shortcut``: OMPL's rope shortcut, then vertex reduction; ``full``:
    ``SimpleSetup.simplifySolution`` (also B-spline smoothing, repeated until
    nothing improves or the budget ends). Measured in the shelf: shortcut paths
    are as short, at a twelfth of the validity checks."""
    check_resolution: float = 0.005
    """Motion validation while planning: checked every this fraction of the
    joint space's extent (OMPL's state validity checking resolution; 0.065 rad
    on the Panda). The final path is checked all along whatever this is
    (:mod:`cbp.collision.motion`)."""
    range: float = 1.0
    """RRT-Connect's step length [rad] (0: OMPL's default, a fifth of the joint
    space's extent: 2.7 rad on the Panda). Measured in the shelf (``cbp bench``):
    1 rad needs a fifth of the validity checks of OMPL's default."""
    waypoint_step: float = 0.05
    """The simplified path is resampled to this joint spacing for timing [rad]."""
    look: LookSettings = field(default_factory=LookSettings)
    """Where the goal lies in unseen space: look at it with the arm's camera
    before planning."""

    def __post_init__(self) -> None:
        """Sensible fractions and steps."""
        if not 0 <= self.simplify_fraction < 1:
            raise ConfigError(
                f"must be in [0, 1), got {self.simplify_fraction}", "simplify_fraction"
            )
        require(self, "> 0", "check_resolution", "waypoint_step")
        require(self, ">= 0", "range")


@dataclass(frozen=True, kw_only=True)
class MpSettings(PlannerSettings):
    """The ``method.mp:`` section: OMPL RRT-Connect to the IK goal."""

    timing: ExecutorTiming = field(
        default_factory=lambda: ExecutorTiming(period=0.25, max_period=4.0)
    )
    """Command period (the paper: a nominal 4 Hz, adaptive), budget, limits."""


@dataclass(frozen=True, kw_only=True)
class HybridSettings:
    """The ``method.hybrid:`` section: CAT, and a planner where CAT stalls.

    CAT itself runs with the ``method.cat`` section (its timing is the loop's);
    these settings say when CAT counts as stalled, how the planner searches,
    and when control returns to CAT. ``scenarios/configs/hybrid.yaml`` sets
    each one with its reason.
    """

    stall_time: float = 0.6
    """CAT is stalled when, for this long [s], ..."""
    stall_progress: float = 0.005
    """... the goal error has shrunk by less than this [m, or rad weighted by
    ``rotation_weight``] ..."""
    stall_error: float = 0.02
    """... while it is above this [m, same weighting] (a goal within it counts
    as reached) ..."""
    goal_still: float = 0.01
    """... the goal has moved less than this [m, same weighting] ..."""
    rotation_weight: float = 0.1
    """(errors and goal motions are position [m] + this x rotation [rad]) ..."""
    require_blocked: bool = True
    """... and, when true, hard constraints other than the step limits
    (contacts, joint limits) were active at CAT's last step: a goal out of
    reach, where nothing blocks the arm, is not planned for."""
    planning_budget: float = 1.5
    """Time the planner may use for one goal, over as many command periods as
    it takes (the arm holds meanwhile) [s of the loop's clock]."""
    tries: int = 3
    """Searches for one goal at most: a search that finds no configuration or
    no plan is started again (fresh random starts, a new RRT-Connect) ..."""
    retry_after: float = 2.0
    """... this long after the last one failed, while CAT stays stalled [s]."""
    goal_moved: float = 0.05
    """While planning or following a plan, a goal that moves more than this
    from the one planned for [m, same weighting] returns control to CAT at the
    next period."""
    ik_seeds: int = 16
    """Configurations the IK search starts from with every joint free: the
    current one, the middle of the joint ranges, and seeded random ones (the
    first collision-free solution is planned to; then the redundant joint is
    swept around the current configuration)."""
    seed: int = 0
    """Seed of the random IK starts."""
    planner: PlannerSettings = field(default_factory=PlannerSettings)
    """IK search and RRT-Connect (the settings of ``method.mp`` minus timing)."""

    def __post_init__(self) -> None:
        """Positive times and thresholds."""
        require(
            self,
            "> 0",
            "stall_time",
            "stall_error",
            "planning_budget",
            "goal_moved",
        )
        require(
            self,
            ">= 0",
            "stall_progress",
            "goal_still",
            "rotation_weight",
            "retry_after",
        )
        require_between(self, 1, 10_000, "starts", "ik_seeds")
        require_between(self, 1, 1000, "searches", "tries")
        require(self, ">= 0", "seed")


@dataclass(frozen=True, kw_only=True)
class JtSettings:
    """The ``method.jt:`` section: Jacobian-transpose torque control (eqs. 6-8)."""

    stiffness_translation: float = 1500.0
    """Cartesian stiffness on the position error [N/m]."""
    stiffness_rotation: float = 80.0
    """Cartesian stiffness on the rotation error [N m/rad]."""
    damping_translation: float = 100.0
    """Cartesian damping on the hand's linear velocity [N s/m]."""
    damping_rotation: float = 5.0
    """Cartesian damping on the hand's angular velocity [N m s/rad]."""
    max_force: float = 100.0
    """Cap on the commanded force's magnitude [N] (the paper limited the wrench)."""
    max_torque: float = 10.0
    """Cap on the commanded moment's magnitude [N m]."""
    nullspace_stiffness: float = 5.0
    """k of eq. 7, toward the initial posture [N m/rad]."""
    joint_damping: float = 1.0
    """Joint damping [N m s/rad]."""

    def __post_init__(self) -> None:
        """Positive gains and caps."""
        require(
            self,
            "> 0",
            "stiffness_translation",
            "stiffness_rotation",
            "max_force",
            "max_torque",
        )
        require(
            self,
            ">= 0",
            "damping_translation",
            "damping_rotation",
            "nullspace_stiffness",
            "joint_damping",
        )


@dataclass(frozen=True, kw_only=True)
class VelocitySettings:
    """The ``method.velocity:`` section: one QP per control tick, velocities out."""

    dt: float = 0.02
    """Control tick [s]; entry gains are per tick (k [1/s] times dt)."""
    transient_s: float = 5.0
    """Metrics of the orbit skip this first part of the run [s] (the initial
    convergence onto the constraints)."""

    def __post_init__(self) -> None:
        """A tick between 0.1 ms and 1 s, non-negative transient."""
        require_between(self, MIN_DT, MAX_DT, "s", "dt")
        require(self, ">= 0", "transient_s")
