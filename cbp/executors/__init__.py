# SPDX-License-Identifier: Apache-2.0
"""Executors: ways of turning the engine's steps into robot motion, in one table.

Each executor is declared once, in :data:`EXECUTORS`: its name (``method.name``
in a scenario, ``--method`` on the command line), the schema of its settings
(the ``method.<name>:`` section), the module that runs it, and whether
``cbp compare`` can put it beside the others. The scenario schema, the command
line and ``cbp compare`` all read this table; the modules that run executors
(PyBullet, OMPL) are imported only when one is used (:meth:`ExecutorInfo.load`).

To add an executor: write ``cbp/executors/<name>.py`` with a module-level
``EXECUTOR`` object that follows :class:`Executor`, put its settings dataclass in
:mod:`cbp.executors.settings`, and add a line to the table.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from cbp.errors import require_choice
from cbp.executors.settings import (
    CatSettings,
    IkSettings,
    JtSettings,
    KinematicSettings,
    MpSettings,
    VelocitySettings,
)

if TYPE_CHECKING:
    from cbp.scenario.runtime import Scenario

__all__ = [
    "COMPARABLE",
    "EXECUTORS",
    "Executor",
    "ExecutorInfo",
    "executor_info",
    "single_run",
]


class Executor(Protocol):
    """What an executor module provides (its ``EXECUTOR`` object)."""

    def run(self, scenario: Scenario, gui: bool = False) -> Any:
        """Run ``scenario`` for its duration; return the executor's trace."""

    def write(
        self, scenario: Scenario, traces: Mapping[str, Any], out: Path
    ) -> dict[str, dict[str, Any]]:
        """Write the outputs of one or more runs into ``out``; metrics by method."""

    def describe(
        self, scenario: Scenario, method: str, metrics: Mapping[str, Any]
    ) -> str:
        """One line that sums up a run, for the terminal."""


@dataclass(frozen=True)
class ExecutorInfo:
    """One row of the executor table.

    Attributes:
        name: the method name.
        settings: the dataclass of its ``method.<name>:`` section.
        module: the module (under ``cbp.executors``) whose ``EXECUTOR`` runs it.
        summary: one sentence for help texts and the schema's documentation.
        comparable: it runs in the simulator and returns a
            :class:`~cbp.trace.RunTrace`, so ``cbp compare`` can run it beside
            the others on one recorded goal stream.
    """

    name: str
    settings: type[Any]
    module: str
    summary: str
    comparable: bool = False

    def load(self) -> Executor:
        """Import the executor's module and return its ``EXECUTOR``."""
        module = importlib.import_module(f"cbp.executors.{self.module}")
        executor: Executor = module.EXECUTOR
        return executor


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
        ),
        ExecutorInfo(
            "ik",
            IkSettings,
            "ik",
            "collision-aware IK near the current configuration, then a checked "
            "joint-space line",
            comparable=True,
        ),
        ExecutorInfo(
            "mp",
            MpSettings,
            "mp",
            "OMPL RRT-Connect to the IK goal, replanned at an adaptive period",
            comparable=True,
        ),
        ExecutorInfo(
            "jt",
            JtSettings,
            "jt",
            "Jacobian-transpose torque control at 1 kHz, no collision avoidance",
            comparable=True,
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


def single_run(traces: Mapping[str, Any], executor: str) -> tuple[str, Any]:
    """The one (method, trace) of ``traces``, for executors that write one run.

    Raises:
        ValueError: there is more than one.
    """
    (method, trace), *more = traces.items()
    if more:
        raise ValueError(f"the {executor} executor writes one run at a time")
    return method, trace
