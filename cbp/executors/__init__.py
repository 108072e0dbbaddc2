# SPDX-License-Identifier: Apache-2.0
"""Executors: ways of turning the engine's steps into robot motion, in one table.

Each executor is declared once, in :data:`EXECUTORS`: its name (``method.name``
in a scenario, ``--method`` on the command line), the schema of its settings
(the ``method.<name>:`` section), the module that runs it, and whether
``cbp compare`` can put it beside the others. The scenario schema, the command
line and ``cbp compare`` all read this table; the modules that run executors
(PyBullet, OMPL) are imported only when one is used (:meth:`ExecutorInfo.load`).

Every executor returns a :class:`~cbp.trace.Trace`, so one writer
(:func:`cbp.report.write_outputs`) gives every method its metrics, figures and
report.

To add an executor: write ``cbp/executors/<name>.py`` with a function
``run_<name>(scenario, gui=False)`` (an :data:`Executor`) that returns a
:class:`~cbp.trace.Trace`, put its settings dataclass in
:mod:`cbp.executors.settings`, and add a line to the table.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from cbp.errors import ConfigError, require_choice
from cbp.executors.settings import (
    CatSettings,
    HybridSettings,
    IkSettings,
    JtSettings,
    KinematicSettings,
    MpSettings,
    VelocitySettings,
)

if TYPE_CHECKING:
    from cbp.executors.simulated import SimulatedRun
    from cbp.executors.trajectory import Planner
    from cbp.scenario.runtime import Scenario
    from cbp.trace import Trace

__all__ = [
    "COMPARABLE",
    "EXECUTORS",
    "PERIODIC",
    "Executor",
    "ExecutorInfo",
    "executor_info",
]


#: Runs a scenario for its duration (``run(scenario, gui)``; ``gui`` opens the
#: simulator's window where there is one) and returns the trace.
Executor = Callable[["Scenario", bool], "Trace"]


@dataclass(frozen=True)
class ExecutorInfo:
    """One row of the executor table.

    Attributes:
        name: the method name.
        settings: the dataclass of its ``method.<name>:`` section.
        module: the module (under ``cbp.executors``) whose ``run_<name>`` runs it.
        summary: one sentence for help texts and the schema's documentation.
        comparable: it tracks a goal in the simulator, so ``cbp compare`` can
            run it beside the others on one recorded goal stream.
        periodic: it plans a path each command period for the trajectory loop
            (:mod:`cbp.executors.trajectory`); its module's ``make_planner``
            gives the planner to other loops (``cbp teleop`` switches among
            these).
        perceives: it runs the depth cameras and their map
            (``perception.source: depth_camera``); the others refuse it
            (:meth:`check`).
        fresh_process: a run needs a process of its own to be reproducible
            (OMPL seeds its random numbers once per process); sweeps give each
            such run a new worker process.
    """

    name: str
    settings: type[Any]
    module: str
    summary: str
    comparable: bool = False
    periodic: bool = False
    perceives: bool = False
    fresh_process: bool = False

    def check(self, scenario: Scenario) -> None:
        """Refuse a scenario this executor cannot run as written.

        Raises:
            ConfigError: the scenario asks for the depth cameras and this
                executor builds no map (it would run blind to the obstacles
                the cameras were to show).
        """
        if scenario.spec.perception.source == "depth_camera" and not self.perceives:
            perceiving = ", ".join(n for n, e in EXECUTORS.items() if e.perceives)
            raise ConfigError(
                f"the {self.name} executor builds no map from depth cameras; "
                f"use perception.source: ground_truth, or a method that does "
                f"({perceiving})",
                f"{scenario.path}: perception.source",
            )

    def load(self) -> Executor:
        """Import the executor's module and return its ``run_<name>`` function."""
        module = importlib.import_module(f"cbp.executors.{self.module}")
        executor: Executor = getattr(module, f"run_{self.name}")
        return executor

    def make_planner(self, scenario: Scenario, run: SimulatedRun) -> Planner:
        """The executor's per-period planner for ``run`` (periodic executors).

        Raises:
            ValueError: the executor does not plan per command period.
        """
        if not self.periodic:
            raise ValueError(f"the {self.name} executor has no per-period planner")
        module = importlib.import_module(f"cbp.executors.{self.module}")
        planner: Planner = module.make_planner(scenario, run)
        return planner


#: Every executor, in the order reports list them.
EXECUTORS: dict[str, ExecutorInfo] = {
    info.name: info
    for info in (
        ExecutorInfo(
            "kinematic",
            KinematicSettings,
            "kinematic",
            "integrate each QP step exactly, no simulator",
        ),
        ExecutorInfo(
            "cat",
            CatSettings,
            "cat",
            "constraint-aware teleoperation: many validated QP steps per command "
            "period, spliced trajectories (CAT paper)",
            comparable=True,
            periodic=True,
            perceives=True,
        ),
        ExecutorInfo(
            "ik",
            IkSettings,
            "ik",
            "collision-aware IK near the current configuration, then a checked "
            "joint-space line",
            comparable=True,
            periodic=True,
            perceives=True,
        ),
        ExecutorInfo(
            "mp",
            MpSettings,
            "mp",
            "OMPL RRT-Connect to the IK goal, replanned at an adaptive period",
            comparable=True,
            periodic=True,
            perceives=True,
            fresh_process=True,
        ),
        ExecutorInfo(
            "hybrid",
            HybridSettings,
            "hybrid",
            "CAT, and where CAT stalls an IK search and an OMPL plan spliced in "
            "(control returns to CAT when the goal moves or the plan ends)",
            comparable=True,
            periodic=True,
            perceives=True,
            fresh_process=True,
        ),
        ExecutorInfo(
            "jt",
            JtSettings,
            "jt",
            "Jacobian-transpose torque control at 1 kHz, no collision avoidance",
            comparable=True,
            perceives=True,
        ),
        ExecutorInfo(
            "velocity",
            VelocitySettings,
            "velocity",
            "one QP per control tick, velocities to a mobile manipulator (orbit "
            "object, pan object)",
        ),
    )
}

#: The executors ``cbp compare`` accepts, in table order.
COMPARABLE = tuple(name for name, info in EXECUTORS.items() if info.comparable)
#: The executors that plan per command period (``cbp teleop --method``).
PERIODIC = tuple(name for name, info in EXECUTORS.items() if info.periodic)


def executor_info(name: str, choices: tuple[str, ...] | None = None) -> ExecutorInfo:
    """The table row of ``name``.

    Args:
        name: a method name.
        choices: the names accepted here (default: every executor).

    Raises:
        ConfigError: ``name`` is not among them; the message lists them and the
            nearest one.
    """
    require_choice(name, EXECUTORS if choices is None else choices, "method", "")
    return EXECUTORS[name]
