# SPDX-License-Identifier: Apache-2.0
"""The schema of a scenario file: one frozen dataclass per section.

:func:`cbp.scenario.load_scenario` builds these from YAML with located errors
(:mod:`cbp.schema`); tasks and constraints are bound to plugins there. The
``method:`` section (:class:`cbp.methods.MethodSpec`) is declared beside the
method table, one settings section per row; the scenario package imports no
executor.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from cbp.collision.settings import CollisionSettings
from cbp.errors import ConfigError, require_choice
from cbp.files import check_folder_name
from cbp.goals import GoalSpec
from cbp.methods import MethodSpec
from cbp.perception.spec import PerceptionSpec
from cbp.robot import BaseType
from cbp.scenario.scene import ObjectSpec, SimulationSettings, SimulatorName
from cbp.solvers import SOLVERS

__all__ = [
    "InputSpec",
    "MethodSpec",
    "ObjectSpec",
    "RobotSpec",
    "ScenarioSpec",
    "SolverSpec",
    "WorldSpec",
]


@dataclass(frozen=True, kw_only=True)
class RobotSpec:
    """The ``robot:`` section."""

    name: str
    """Robot folder under ``robots/`` (or a path to one)."""
    base: BaseType | None = None
    """``fixed``, ``planar`` (x, y, yaw) or ``floating``; default: the robot's
    own (robot.yaml's ``base``)."""
    initial: dict[str, float] = field(default_factory=dict)
    """Initial joint positions by name [rad or m]; others start at home."""
    allow_initial_contact: bool = False
    """Accept an initial configuration that penetrates a declared object by up
    to 40 mm (the arm then backs out); by default, or deeper, the scenario is
    refused, naming the link, the object and the depth."""


@dataclass(frozen=True, kw_only=True)
class SolverSpec:
    """The ``solver:`` section."""

    name: str = "daqp"
    """QP backend: one of :data:`cbp.solvers.SOLVERS` (daqp, piqp, cvxpy)."""
    regularization: float = 1e-9
    """Added to the diagonal of the QP cost matrix."""

    def __post_init__(self) -> None:
        """A known backend; regularization must be positive."""
        require_choice(self.name, SOLVERS, "solver", "name")
        if not self.regularization > 0:
            raise ConfigError(
                f"must be > 0, got {self.regularization}", "regularization"
            )


@dataclass(frozen=True, kw_only=True)
class InputSpec:
    """One live operator input: values for an entry's ``set_input``, as functions of t.

    The orbit's user velocity and desired distance are inputs; so is anything a
    plugin exposes through ``set_input``.
    """

    entry: str
    """Name of the task or constraint entry that takes the input."""
    values: list[str | float]
    """One number or expression of ``t`` per input value (see
    :mod:`cbp.expressions`)."""


@dataclass(frozen=True, kw_only=True)
class WorldSpec:
    """The ``world:`` section: the objects around the robot."""

    objects: list[ObjectSpec] = field(default_factory=list)
    """Objects, in the world frame."""


#: Longest run a scenario may ask for [s] (a day).
MAX_DURATION = 86400.0


@dataclass(frozen=True, kw_only=True)
class ScenarioSpec:
    """A whole scenario file (tasks and constraints are bound separately)."""

    name: str
    """Scenario name, used for output folders."""
    description: str = ""
    """What the scenario shows."""
    robot: RobotSpec
    """The robot."""
    duration: float
    """Length of a run [s]."""
    method: MethodSpec = field(default_factory=MethodSpec)
    """The executor and its timing."""
    solver: SolverSpec = field(default_factory=SolverSpec)
    """The QP backend."""
    goal: GoalSpec | None = None
    """The goal input, if any."""
    world: WorldSpec = field(default_factory=WorldSpec)
    """The objects around the robot."""
    simulation: SimulationSettings = field(default_factory=SimulationSettings)
    """Physics rate and the joint impedance of the simulated robot."""
    simulator: SimulatorName = "pybullet"
    """The physics engine: ``pybullet``, or ``mujoco`` (the ``mujoco`` extra;
    fixed-base robots)."""
    collision: CollisionSettings = field(default_factory=CollisionSettings)
    """Contact queries and step validation."""
    perception: PerceptionSpec = field(default_factory=PerceptionSpec)
    """Where the collision world's environment comes from."""
    inputs: list[InputSpec] = field(default_factory=list)
    """Live operator inputs to entries (velocity executor), functions of time."""
    tasks: Any = None
    """Task entries (bound by :func:`load_scenario`)."""
    constraints: Any = None
    """Constraint entries (bound by :func:`load_scenario`)."""

    def __post_init__(self) -> None:
        """A positive duration of at most a day; a name that is a folder name."""
        check_folder_name(self.name)
        if not 0 < self.duration <= MAX_DURATION:
            raise ConfigError(
                f"must be in (0, {MAX_DURATION:g}] s, got {self.duration}", "duration"
            )
