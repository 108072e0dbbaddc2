# SPDX-License-Identifier: Apache-2.0
r"""The drift of a moving robot's constraint rows over a step, ahead of the solve.

A constraint row bounds :math:`J\,\Delta q`, the first-order change of its
value over the step. A robot that moves changes it by more: a turning base
carries its frames along arcs, an arm its frames along curves. Near a bound
that second-order term, repeated every step, walks the value past it (for a
base turning at 0.8 rad/s and sliding along an obstacle at 0.13 m/s, 18 um a
20 ms tick: with k = 0.04, 0.4 mm past the bound at rest). When a step is
given the robot's velocity, :class:`CoastingDrift` measures the term for the
step the robot is most of the way committed to (coasting at ``v``; the
acceleration limits keep the real step within :math:`a\,\Delta t^2` of it)
and moves the rows' bounds by it. The bounds of a constraint that move at a
steady rate (the orbit's desired distance, an operator's input;
:class:`cbp.plugin.MovingBounds`) are moved by as much as they will move over
the step, so that the rows follow them without the feedback's lag.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cbp.plugin import AnyPlugin, Constraint, MovingBounds, UsesCollisionWorld
from cbp.qp import Entry, QPProblem
from cbp.robot import FloatArray, IntArray, RobotModel
from cbp.state import RobotState

__all__ = ["CoastingDrift"]

#: A row within this of one of its bounds holds the step [its unit].
ACTIVE = 1e-9

#: Inequality rows that drift are tightened by this [their unit per step]: ten
#: times the solver's tolerance, so that a robot held on a bound step after
#: step (sliding along it) stays on its side (the feedback form adds up the
#: solver's errors to error / k there).
SOLVER_MARGIN = 1e-8


class CoastingDrift:
    r"""Moves hard constraint rows by the drift of coasting one step.

    With :math:`q^+ = q \oplus v\,\Delta t`, each row gets
    :math:`\delta = f(q^+) - f(q) - J\,v\,\Delta t` and its bounds
    :math:`k(l - f) - \delta` and :math:`k(u - f) - \delta`: the row then
    bounds the value the step ends at, to within the change of velocity the
    acceleration limits allow (third order in the step).

    Rows of hard constraints only, and not those of the robot's own limits
    (joint-space rows are linear), of entries with a constant Jacobian, or of
    entries that read contacts (their rows follow the contacts latched at the
    step's start).

    Args:
        robot: the robot model.
        entries: the engine's entries, in order.
    """

    def __init__(self, robot: RobotModel, entries: Sequence[Entry]) -> None:
        """Pick the entries whose rows drift."""
        self.robot = robot
        self.plugins: list[tuple[int, AnyPlugin]] = [
            (i, e.plugin) for i, e in enumerate(entries) if _drifts(e)
        ]
        self._ahead = RobotState(robot) if self.plugins else None
        self._rows: list[IntArray] = []
        self.moving: list[tuple[int, MovingBounds]] = [
            (i, e.plugin)
            for i, e in enumerate(entries)
            if isinstance(e.plugin, MovingBounds) and e.priority == "hard"
        ]
        self._moving_rows: list[IntArray] = []
        #: The coasting drift applied to each plugin's rows at this step.
        self._applied: list[tuple[int, FloatArray]] = []
        #: Each plugin's value at the step's start; all their rows.
        self._start: dict[int, FloatArray] = {}
        self._all: IntArray = np.zeros(0, dtype=np.intp)

    def apply(
        self,
        problem: QPProblem,
        values: FloatArray,
        state: RobotState,
        v: FloatArray,
        dt: float,
    ) -> None:
        """Move the rows' bounds in ``problem`` by the drift of coasting at ``v``.

        ``values`` are the rows' values as assembled (:attr:`cbp.qp.QPAssembler.values`)
        and ``state`` the step's start; a plugin whose value cannot be computed
        ahead (a singular configuration) keeps its rows as assembled.
        """
        if self.moving:
            self._follow(problem)
        self._applied = []
        if self._ahead is None or not v.any():
            return
        if not self._rows:
            self._rows = [
                np.flatnonzero(problem.row_entry == i) for i, _ in self.plugins
            ]
            self._all = np.concatenate(self._rows)
        self._start = {k: values[rows] for k, rows in enumerate(self._rows)}
        self._applied = self._drift(problem, state, v * dt, list(self._start))
        for k, drift in self._applied:
            rows = self._rows[k]
            margin = np.where(problem.equality[rows], 0.0, SOLVER_MARGIN)
            problem.lower[rows] -= drift - margin  # an infinite bound stays so
            problem.upper[rows] -= drift + margin

    def refine(self, problem: QPProblem, state: RobotState, dq: FloatArray) -> bool:
        """Move the rows that hold the step by the drift of ``dq``, not coasting's.

        The step found (``dq``) differs from coasting by the change of
        velocity; for the inequality rows at one of their bounds that is the
        drift's last error. Returns whether a row moved (then solve again).
        """
        if not self._applied:
            return False
        rows = self._all
        at = problem.A[rows, : problem.nv].dot(dq)
        active = np.zeros(problem.A.shape[0], dtype=bool)
        active[rows] = ~problem.equality[rows] & (
            (np.abs(at - problem.lower[rows]) <= ACTIVE)
            | (np.abs(problem.upper[rows] - at) <= ACTIVE)
        )
        if not active[rows].any():
            return False
        holding = [(k, d) for k, d in self._applied if active[self._rows[k]].any()]
        moved = False
        found = dict(self._drift(problem, state, dq, [k for k, _ in holding]))
        for k, coasting in holding:
            if k not in found:
                continue
            mine = self._rows[k]
            shift = np.where(active[mine], found[k] - coasting, 0.0)
            problem.lower[mine] -= shift
            problem.upper[mine] -= shift
            moved = moved or bool(np.any(shift != 0.0))
        return moved

    def _drift(
        self, problem: QPProblem, state: RobotState, step: FloatArray, which: list[int]
    ) -> list[tuple[int, FloatArray]]:
        """(index, f(q ⊕ step) - f(q) - J step) of the plugins ``which``.

        Those whose values can be computed there and are finite.
        """
        ahead = self._ahead
        assert ahead is not None  # only called with plugins that drift
        ahead.update(self.robot.integrate(state.q, step))
        A = problem.A
        out = []
        for k in which:
            plugin, rows = self.plugins[k][1], self._rows[k]
            try:
                change = plugin.compute_value(ahead) - self._start[k]
            except (ArithmeticError, ValueError):
                continue
            drift = change - A[rows, : problem.nv].dot(step)
            if np.all(np.isfinite(drift)):
                out.append((k, drift))
        return out

    def _follow(self, problem: QPProblem) -> None:
        """Move the moving bounds' rows by how far the bounds move over the step."""
        if not self._moving_rows:
            self._moving_rows = [
                np.flatnonzero(problem.row_entry == i) for i, _ in self.moving
            ]
        for rows, (_, plugin) in zip(self._moving_rows, self.moving, strict=True):
            change = np.asarray(plugin.bound_change(), dtype=float)
            if change.shape != rows.shape or not np.all(np.isfinite(change)):
                continue
            problem.lower[rows] += change
            problem.upper[rows] += change


def _drifts(entry: Entry) -> bool:
    """Whether an entry's rows are moved by the drift (see :class:`CoastingDrift`)."""
    plugin = entry.plugin
    return (
        isinstance(plugin, Constraint)
        and entry.priority == "hard"
        and plugin.robot_limit is None
        and plugin.easable
        and not plugin.constant_jacobian
        and not isinstance(plugin, UsesCollisionWorld)
    )
