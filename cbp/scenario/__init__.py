# SPDX-License-Identifier: Apache-2.0
"""Scenarios: schema (:mod:`.spec`), loading (:mod:`.load`), runtime (:mod:`.runtime`).

Dependencies point one way: ``load`` builds a ``spec`` and returns a ``runtime``
:class:`Scenario`; executors import only ``runtime``.
"""

from cbp.scenario.load import load_scenario
from cbp.scenario.runtime import Scenario
from cbp.scenario.spec import (
    InputSpec,
    MethodSpec,
    ObjectSpec,
    RobotSpec,
    ScenarioSpec,
    SolverSpec,
    WorldSpec,
)

__all__ = [
    "InputSpec",
    "MethodSpec",
    "ObjectSpec",
    "RobotSpec",
    "Scenario",
    "ScenarioSpec",
    "SolverSpec",
    "WorldSpec",
    "load_scenario",
]
