# SPDX-License-Identifier: Apache-2.0
"""The engine: one QP per step from a list of task and constraint entries."""

from __future__ import annotations

from collections.abc import Sequence

from cbp.errors import ConfigError, suggestion
from cbp.plugin import AnyPlugin, Plugin
from cbp.qp import Entry, QPAssembler, QPProblem
from cbp.robot import FloatArray, RobotModel
from cbp.solvers import QPSolver, make_solver
from cbp.state import RobotState


class Engine:
    """Computes the joint displacement of one step: kinematics, QP assembly, solve.

    Args:
        robot: the robot model.
        entries: tasks and constraints with their engine-level settings.
        solver: a backend name (``daqp``, ``piqp``, ``cvxpy``) or instance.
        regularization: added to the diagonal of the QP's cost matrix.

    Attributes:
        state: the state of the last step (kinematics at its start).
        problem: the QP of the last step, for inspection.
    """

    def __init__(
        self,
        robot: RobotModel,
        entries: Sequence[Entry],
        solver: str | QPSolver = "daqp",
        regularization: float = 1e-9,
    ) -> None:
        """Lay out the QP and pick the backend."""
        names = [e.name for e in entries]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ConfigError(
                f"entry names must be unique; repeated: {', '.join(duplicates)} "
                "(give each entry its own 'name')"
            )
        self.robot = robot
        self.entries = list(entries)
        self.solver = make_solver(solver) if isinstance(solver, str) else solver
        self.assembler = QPAssembler(self.entries, robot.nv, regularization)
        self.state = RobotState(robot)
        self.problem: QPProblem | None = None
        self._by_name = {e.name: e for e in self.entries}
        # Plugins that latch something at the start of a step (the others keep
        # the base class's empty prepare and are not called for it).
        plugins = [e.plugin for e in self.entries]
        self._latching = [p for p in plugins if type(p).prepare is not Plugin.prepare]

    def plugin(self, name: str) -> AnyPlugin:
        """Return the plugin of the entry called ``name``."""
        try:
            return self._by_name[name].plugin
        except KeyError:
            raise ConfigError(
                f"no entry named '{name}'{suggestion(name, self._by_name)} "
                f"Entries: {', '.join(self._by_name)}."
            ) from None

    def step(self, q: FloatArray, dt: float) -> FloatArray:
        """Return the displacement dq (nv) of one step of duration ``dt`` from ``q``.

        Raises:
            SolveError: the QP is infeasible or the backend failed; nothing moved.
            PluginOutputError: a plugin returned a malformed or non-finite output.
        """
        state = self.state
        state.update(q)
        for plugin in self._latching:
            plugin.prepare(state, dt)
        problem = self.assembler.assemble(state)
        self.problem = problem
        x = self.solver.solve(problem)
        return x[: self.robot.nv]
