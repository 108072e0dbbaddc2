# SPDX-License-Identifier: Apache-2.0
"""The method table: every way of running a scenario, declared once.

Each row of :data:`METHODS` says what a method is (its name, as in
``method.name`` and ``--method``), the schema of its settings (the
``method.<name>:`` section, :mod:`cbp.methods.settings`), the module under
:mod:`cbp.executors` that runs it, its colour in every figure and page, and
what it can do. The scenario schema, the command line, ``cbp compare``, the
sweeps, the figures and the pages all read this table.

The scenario's ``method:`` section (:class:`MethodSpec`, one settings section
per row) is declared here too, beside the rows.

This package is plain data: it imports no executor, simulator or planner, so
the scenario package takes its ``method:`` section from it while the
executors (above it) run what it names (:func:`cbp.executors.load_executor`).

To add a method: write ``cbp/executors/<name>.py`` with ``run_<name>(scenario,
gui=False)`` returning a :class:`~cbp.trace.Trace` (and ``make_planner(scenario,
parts)`` if it plans per command period), put its settings dataclass in
:mod:`cbp.methods.settings`, and here a row and a field of :class:`MethodSpec`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, TypeVar

from cbp.errors import ConfigError, require_choice
from cbp.methods.settings import (
    CatSettings,
    ExecutorTiming,
    HybridSettings,
    IkSettings,
    JtSettings,
    KinematicSettings,
    MpSettings,
    VelocitySettings,
)

__all__ = [
    "COMPARABLE",
    "METHODS",
    "PERIODIC",
    "Method",
    "MethodSpec",
    "method_colour",
    "method_info",
]

T = TypeVar("T")

#: The colour of a run whose method is not in the table (RGB 0-255).
OTHER_COLOUR = (127, 127, 127)


@dataclass(frozen=True)
class Method:
    """One row of the method table.

    Attributes:
        name: the method name.
        settings: the dataclass of its ``method.<name>:`` section.
        module: the module under ``cbp.executors`` whose ``run_<name>`` runs it.
        summary: one sentence for help texts and the schema's documentation.
        colour: its colour in figures and pages, RGB 0-255 (the paper's: CAT
            blue, IK green, MP orange, JT red; hybrid purple).
        comparable: it tracks a goal in the simulator, so ``cbp compare`` can
            run it beside the others on one recorded goal stream.
        periodic: it plans a path each command period for the trajectory loop
            (:mod:`cbp.run.loop`); its module's ``make_planner``
            gives the planner to other loops (``cbp teleop`` switches among
            these).
        timing: for a periodic method, the method whose settings section
            holds the loop's timing (``timing:``): its own, or CAT's for the
            hybrid, which runs CAT's loop.
        perceives: it runs the depth cameras and their map
            (``perception.source: depth_camera``); the others refuse it.
        checks_collisions: its planner checks configurations and motions
            against the collision world itself (an IK search, a motion
            planner), so a run of it builds the world even when no entry of
            the scenario reads contacts.
        fresh_process: its planners keep process-wide state that a seed cannot
            reset (OMPL seeds its samplers once per process), so a sweep runs
            each of its runs in a new worker process to be reproducible.
        commands_velocity: it gives each engine step the robot's last command,
            so the step guard checks the acceleration limits; a scenario of it
            that keeps no acceleration limits gets ``joint_acceleration``'s
            rows from the robot's limits (the loader says so).
    """

    name: str
    settings: type[Any]
    module: str
    summary: str
    colour: tuple[int, int, int]
    comparable: bool = False
    periodic: bool = False
    timing: str | None = None
    perceives: bool = False
    checks_collisions: bool = False
    fresh_process: bool = False
    commands_velocity: bool = False

    def refuse_source(self, source: str, where: str) -> None:
        """Refuse an obstacle source this method cannot use.

        Args:
            source: the scenario's ``perception.source``.
            where: where the source was written (a file and key), for the error.

        Raises:
            ConfigError: the source is the depth cameras and this method builds
                no map (it would run blind to the obstacles the cameras were
                to show).
        """
        if source == "depth_camera" and not self.perceives:
            perceiving = ", ".join(n for n, m in METHODS.items() if m.perceives)
            raise ConfigError(
                f"the {self.name} executor builds no map from depth cameras; "
                f"use perception.source: ground_truth, or a method that does "
                f"({perceiving})",
                where,
            )


#: Every method, in the order reports list them.
METHODS: dict[str, Method] = {
    row.name: row
    for row in (
        Method(
            "kinematic",
            KinematicSettings,
            "kinematic",
            "integrate each QP step exactly, no simulator",
            colour=(140, 86, 75),
        ),
        Method(
            "cat",
            CatSettings,
            "cat",
            "constraint-aware teleoperation: many validated QP steps per command "
            "period, spliced trajectories (CAT paper)",
            colour=(31, 119, 180),
            comparable=True,
            periodic=True,
            timing="cat",
            perceives=True,
        ),
        Method(
            "ik",
            IkSettings,
            "ik",
            "collision-aware IK near the current configuration, then a checked "
            "joint-space line",
            colour=(44, 160, 44),
            comparable=True,
            periodic=True,
            timing="ik",
            perceives=True,
            checks_collisions=True,
        ),
        Method(
            "mp",
            MpSettings,
            "mp",
            "OMPL RRT-Connect to the IK goal, replanned at an adaptive period",
            colour=(255, 127, 14),
            comparable=True,
            periodic=True,
            timing="mp",
            perceives=True,
            checks_collisions=True,
            fresh_process=True,
        ),
        Method(
            "hybrid",
            HybridSettings,
            "hybrid",
            "CAT, and where CAT stalls an IK search and an OMPL plan spliced in "
            "(control returns to CAT when the goal moves or the plan ends)",
            colour=(148, 103, 189),
            comparable=True,
            periodic=True,
            timing="cat",
            perceives=True,
            checks_collisions=True,
            fresh_process=True,
        ),
        Method(
            "jt",
            JtSettings,
            "jt",
            "Jacobian-transpose torque control at 1 kHz, no collision avoidance",
            colour=(214, 39, 40),
            comparable=True,
            perceives=True,
        ),
        Method(
            "velocity",
            VelocitySettings,
            "velocity",
            "one QP per control tick, velocities to a mobile manipulator (orbit "
            "object, pan object)",
            colour=(23, 190, 207),
            commands_velocity=True,
        ),
    )
}

#: The methods ``cbp compare`` accepts, in table order.
COMPARABLE = tuple(name for name, row in METHODS.items() if row.comparable)
#: The methods that plan per command period (``cbp teleop --method``).
PERIODIC = tuple(name for name, row in METHODS.items() if row.periodic)


def method_colour(name: str) -> tuple[int, int, int]:
    """Method ``name``'s colour (RGB 0-255); grey for a name not in the table."""
    row = METHODS.get(name)
    return OTHER_COLOUR if row is None else row.colour


def method_info(name: str, choices: tuple[str, ...] | None = None) -> Method:
    """The table row of ``name``.

    Args:
        name: a method name.
        choices: the names accepted here (default: every method).

    Raises:
        ConfigError: ``name`` is not among them; the message lists them and the
            nearest one.
    """
    require_choice(name, METHODS if choices is None else choices, "method", "")
    return METHODS[name]


@dataclass(frozen=True, kw_only=True)
class MethodSpec:
    """The ``method:`` section: which method runs the scenario, and its settings.

    One settings section per row of the method table (:data:`cbp.methods.METHODS`,
    which says what each method does); only the named method's is used.
    """

    name: str = "kinematic"
    """The method: one of :data:`cbp.methods.METHODS`."""
    kinematic: KinematicSettings = field(default_factory=KinematicSettings)
    """Settings of the kinematic executor."""
    cat: CatSettings = field(default_factory=CatSettings)
    """Settings of constraint-aware teleoperation."""
    ik: IkSettings = field(default_factory=IkSettings)
    """Settings of the IK executor."""
    mp: MpSettings = field(default_factory=MpSettings)
    """Settings of the motion planner (OMPL)."""
    hybrid: HybridSettings = field(default_factory=HybridSettings)
    """Settings of CAT with planning where it stalls."""
    jt: JtSettings = field(default_factory=JtSettings)
    """Settings of Jacobian-transpose control."""
    velocity: VelocitySettings = field(default_factory=VelocitySettings)
    """Settings of the velocity executor (mobile manipulator)."""

    def __post_init__(self) -> None:
        """A known method."""
        require_choice(self.name, METHODS, "method", "name")

    def settings(self, cls: type[T]) -> T:
        """The settings section of type ``cls`` (``method.settings(CatSettings)``)."""
        for row in METHODS.values():
            if row.settings is cls:
                value: T = getattr(self, row.name)
                return value
        raise KeyError(f"no method has settings of type {cls.__name__}")

    def timing(self, name: str) -> ExecutorTiming:
        """The loop timing of periodic method ``name`` (the hybrid runs CAT's).

        Raises:
            ValueError: ``name`` does not plan per command period.
        """
        row = method_info(name)
        if row.timing is None:
            raise ValueError(f"the {name} executor has no per-period planner")
        timing: ExecutorTiming = getattr(self, row.timing).timing
        return timing
