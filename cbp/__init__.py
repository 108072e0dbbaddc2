# SPDX-License-Identifier: Apache-2.0
"""cbp: constraint-based robot control and teleoperation.

A quadratic program is assembled every control step from task plugins (objective
terms) and constraint plugins, declared in YAML scenarios. See :mod:`cbp.plugin` for
the conventions every plugin follows.
"""

from cbp.engine import Engine
from cbp.errors import (
    CbpError,
    ConfigError,
    FrameNotFoundError,
    InvalidTargetError,
    JacobianMismatchError,
    JointNotFoundError,
    PluginOutputError,
    RobotNotFoundError,
    ScenarioError,
    SolveError,
    TargetNotSetError,
    UnknownPluginError,
)
from cbp.plugin import Constraint, Linearization, Plugin, PluginParams, Task
from cbp.qp import Entry, QPAssembler, QPProblem
from cbp.registry import Registry
from cbp.robot import RobotModel
from cbp.scenario import Scenario, load_scenario
from cbp.solvers import SOLVERS, make_solver
from cbp.state import RobotState

__version__ = "0.1.0"

__all__ = [
    "SOLVERS",
    "CbpError",
    "ConfigError",
    "Constraint",
    "Engine",
    "Entry",
    "FrameNotFoundError",
    "InvalidTargetError",
    "JacobianMismatchError",
    "JointNotFoundError",
    "Linearization",
    "Plugin",
    "PluginOutputError",
    "PluginParams",
    "QPAssembler",
    "QPProblem",
    "Registry",
    "RobotModel",
    "RobotNotFoundError",
    "RobotState",
    "Scenario",
    "ScenarioError",
    "SolveError",
    "TargetNotSetError",
    "Task",
    "UnknownPluginError",
    "load_scenario",
    "make_solver",
]
