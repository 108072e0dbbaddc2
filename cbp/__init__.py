# SPDX-License-Identifier: Apache-2.0
"""cbp: constraint-based robot control and teleoperation.

A quadratic program is assembled every control step from task plugins (objective
terms) and constraint plugins, declared in YAML scenarios. See :mod:`cbp.plugin` for
the conventions every plugin follows.
"""

from typing import TYPE_CHECKING, Any

from cbp.errors import (
    CbpError,
    ConfigError,
    FrameNotFoundError,
    InvalidTargetError,
    JacobianMismatchError,
    JointNotFoundError,
    PluginDefinitionError,
    PluginOutputError,
    RobotNotFoundError,
    ScenarioError,
    SolveError,
    TargetNotSetError,
    UnknownPluginError,
)
from cbp.plugin import (
    Constraint,
    GoalReceiver,
    Linearization,
    Plugin,
    PluginParams,
    ReportsSignals,
    TakesInput,
    Task,
    UsesCollisionWorld,
)
from cbp.robot import RobotModel
from cbp.state import RobotState

if TYPE_CHECKING:
    from cbp.engine import Engine
    from cbp.qp import Entry, QPAssembler, QPProblem
    from cbp.registry import Registry
    from cbp.scenario import Scenario, load_scenario
    from cbp.solvers import SOLVERS, make_solver

#: Names imported on first use: the engine's QP layer compiles kernels (numba)
#: and scenarios bring in the collision world (coal, trimesh), which a plugin
#: author importing ``cbp`` does not need.
_LAZY = {
    "Engine": "cbp.engine",
    "Entry": "cbp.qp",
    "QPAssembler": "cbp.qp",
    "QPProblem": "cbp.qp",
    "Registry": "cbp.registry",
    "SOLVERS": "cbp.solvers",
    "Scenario": "cbp.scenario",
    "load_scenario": "cbp.scenario",
    "make_solver": "cbp.solvers",
}


def __getattr__(name: str) -> Any:
    """Import the lazily exported names on first use."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'cbp' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


__version__ = "0.2.0"

__all__ = [
    "SOLVERS",
    "CbpError",
    "ConfigError",
    "Constraint",
    "Engine",
    "Entry",
    "FrameNotFoundError",
    "GoalReceiver",
    "InvalidTargetError",
    "JacobianMismatchError",
    "JointNotFoundError",
    "Linearization",
    "Plugin",
    "PluginDefinitionError",
    "PluginOutputError",
    "PluginParams",
    "QPAssembler",
    "QPProblem",
    "Registry",
    "ReportsSignals",
    "RobotModel",
    "RobotNotFoundError",
    "RobotState",
    "Scenario",
    "ScenarioError",
    "SolveError",
    "TakesInput",
    "TargetNotSetError",
    "Task",
    "UnknownPluginError",
    "UsesCollisionWorld",
    "load_scenario",
    "make_solver",
]
