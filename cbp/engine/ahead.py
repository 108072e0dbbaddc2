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

import math
from collections.abc import Sequence

import numba
import numpy as np
import numpy.typing as npt

from cbp.plugin import AnyPlugin, Constraint, MovingBounds, UsesCollisionWorld
from cbp.qp import Entry, QPProblem
from cbp.robot import FloatArray, IntArray, RobotModel
from cbp.state import RobotState

__all__ = ["CoastingDrift"]

BoolArray = npt.NDArray[np.bool_]

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
        self.moving: list[tuple[int, MovingBounds]] = [
            (i, e.plugin)
            for i, e in enumerate(entries)
            if isinstance(e.plugin, MovingBounds) and e.priority == "hard"
        ]
        self._moving_rows: list[slice] = []
        # Laid out at the first step (see _lay_out): the drifting plugins'
        # rows of the problem, the plugin of each, and per plugin its part of
        # those rows; per row the value at the step's start, the value ahead,
        # the coasting drift applied and whether the row holds the step.
        self._rows: IntArray = np.zeros(0, dtype=np.intp)
        self._owner: IntArray = np.zeros(0, dtype=np.intp)
        self._parts: list[slice] = []
        self._start = np.zeros(0)
        self._value_ahead = np.zeros(0)
        self._coasting = np.zeros(0)
        self._active = np.zeros(0, dtype=np.bool_)
        #: Per plugin: whether its coasting drift was applied at this step.
        self._applied = np.zeros(len(self.plugins), dtype=np.bool_)
        self._any_applied = False
        if self.plugins:
            _compile()

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
        self._any_applied = False
        if self._ahead is None or not v.any():
            return
        if not self._parts:
            self._lay_out(problem)
        np.take(values, self._rows, out=self._start)
        step = v * dt
        applied = self._applied
        applied.fill(True)
        self._values_ahead(state, step, applied)
        self._any_applied = _apply_coasting(
            problem.A,
            problem.nv,
            self._rows,
            self._owner,
            applied,
            self._value_ahead,
            self._start,
            step,
            problem.lower,
            problem.upper,
            problem.equality,
            self._coasting,
        )

    def refine(self, problem: QPProblem, state: RobotState, dq: FloatArray) -> bool:
        """Move the rows that hold the step by the drift of ``dq``, not coasting's.

        The step found (``dq``) differs from coasting by the change of
        velocity; for the inequality rows at one of their bounds that is the
        drift's last error. Returns whether a row moved (then solve again).
        """
        if not self._any_applied:
            return False
        holding = _holding(
            problem.A,
            problem.nv,
            self._rows,
            self._owner,
            self._applied,
            problem.lower,
            problem.upper,
            problem.equality,
            dq,
            self._active,
        )
        if not holding.any():
            return False
        self._values_ahead(state, dq, holding)
        return bool(
            _refine_rows(
                problem.A,
                problem.nv,
                self._rows,
                self._owner,
                holding,
                self._value_ahead,
                self._start,
                dq,
                self._coasting,
                self._active,
                problem.lower,
                problem.upper,
            )
        )

    def _lay_out(self, problem: QPProblem) -> None:
        """Find the drifting plugins' rows and allocate the per-row buffers."""
        parts, rows, owner, used = [], [], [], 0
        for k, (i, _) in enumerate(self.plugins):
            mine = np.flatnonzero(problem.row_entry == i)
            parts.append(slice(used, used + mine.size))
            rows.append(mine)
            owner.append(np.full(mine.size, k))
            used += mine.size
        self._rows = np.concatenate(rows).astype(np.intp)
        self._owner = np.concatenate(owner).astype(np.intp)
        self._start = np.zeros(used)
        self._value_ahead = np.zeros(used)
        self._coasting = np.zeros(used)
        self._active = np.zeros(used, dtype=np.bool_)
        self._parts = parts

    def _values_ahead(
        self, state: RobotState, step: FloatArray, which: BoolArray
    ) -> None:
        """The values at q ⊕ ``step`` of the plugins ``which`` marks, into a buffer.

        A plugin whose value cannot be computed there is unmarked.
        """
        ahead = self._ahead
        assert ahead is not None  # only called with plugins that drift
        ahead.update(self.robot.integrate(state.q, step))
        out = self._value_ahead
        for k, (_, plugin) in enumerate(self.plugins):
            if not which[k]:
                continue
            try:
                out[self._parts[k]] = plugin.compute_value(ahead)
            except (ArithmeticError, ValueError):
                which[k] = False

    def _follow(self, problem: QPProblem) -> None:
        """Move the moving bounds' rows by how far the bounds move over the step."""
        if not self._moving_rows:
            self._moving_rows = [_rows_of(problem, i) for i, _ in self.moving]
        for rows, (_, plugin) in zip(self._moving_rows, self.moving, strict=True):
            change = np.asarray(plugin.bound_change(), dtype=float)
            if change.shape != (rows.stop - rows.start,):
                continue
            if not np.isfinite(change).all():
                continue
            problem.lower[rows] += change
            problem.upper[rows] += change


def _rows_of(problem: QPProblem, entry: int) -> slice:
    """A hard entry's rows of ``problem``: consecutive, as the assembler lays them."""
    rows = np.flatnonzero(problem.row_entry == entry)
    first = int(rows[0]) if rows.size else 0
    if rows.size and int(rows[-1]) - first + 1 != rows.size:
        raise AssertionError(f"the rows of entry {entry} are not consecutive")
    return slice(first, first + int(rows.size))


@numba.njit(cache=True, nogil=True)
def _drift_of(
    A: FloatArray,
    nv: int,
    rows: IntArray,
    owner: IntArray,
    which: BoolArray,
    value_ahead: FloatArray,
    start: FloatArray,
    step: FloatArray,
    drift: FloatArray,
) -> None:
    """f(q ⊕ step) - f(q) - J step of the rows of the plugins ``which`` marks.

    Into ``drift``; a plugin with a non-finite drift is unmarked.
    """
    for j in range(rows.size):
        if not which[owner[j]]:
            continue
        r = rows[j]
        linear = 0.0
        for c in range(nv):
            linear += A[r, c] * step[c]
        drift[j] = (value_ahead[j] - start[j]) - linear
        if not math.isfinite(drift[j]):
            which[owner[j]] = False


@numba.njit(cache=True, nogil=True)
def _apply_coasting(
    A: FloatArray,
    nv: int,
    rows: IntArray,
    owner: IntArray,
    applied: BoolArray,
    value_ahead: FloatArray,
    start: FloatArray,
    step: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    equality: BoolArray,
    coasting: FloatArray,
) -> bool:
    """Move the bounds of the rows of the plugins ``applied`` marks by their drift.

    The drift into ``coasting``; inequality rows are tightened by
    :data:`SOLVER_MARGIN` as well (an infinite bound stays so). A plugin whose
    drift is not finite is unmarked and its rows kept. Returns whether any
    plugin's rows moved.
    """
    _drift_of(A, nv, rows, owner, applied, value_ahead, start, step, coasting)
    any_applied = False
    for j in range(rows.size):
        if not applied[owner[j]]:
            continue
        any_applied = True
        r = rows[j]
        margin = 0.0 if equality[r] else SOLVER_MARGIN
        lower[r] -= coasting[j] - margin
        upper[r] -= coasting[j] + margin
    return any_applied


@numba.njit(cache=True, nogil=True)
def _holding(
    A: FloatArray,
    nv: int,
    rows: IntArray,
    owner: IntArray,
    applied: BoolArray,
    lower: FloatArray,
    upper: FloatArray,
    equality: BoolArray,
    dq: FloatArray,
    active: BoolArray,
) -> BoolArray:
    """The plugins with an applied inequality row at one of its bounds at ``dq``.

    Marks those rows in ``active``.
    """
    holding = np.zeros(applied.size, dtype=np.bool_)
    for j in range(rows.size):
        r = rows[j]
        at = 0.0
        for c in range(nv):
            at += A[r, c] * dq[c]
        active[j] = not equality[r] and (
            abs(at - lower[r]) <= ACTIVE or abs(upper[r] - at) <= ACTIVE
        )
        if active[j] and applied[owner[j]]:
            holding[owner[j]] = True
    return holding


@numba.njit(cache=True, nogil=True)
def _refine_rows(
    A: FloatArray,
    nv: int,
    rows: IntArray,
    owner: IntArray,
    holding: BoolArray,
    value_ahead: FloatArray,
    start: FloatArray,
    dq: FloatArray,
    coasting: FloatArray,
    active: BoolArray,
    lower: FloatArray,
    upper: FloatArray,
) -> bool:
    """Move the active rows of the plugins ``holding`` marks by the drift of ``dq``.

    Less the coasting drift already applied; a plugin whose drift is not
    finite keeps its rows. Returns whether a row moved.
    """
    found = np.empty(rows.size)
    _drift_of(A, nv, rows, owner, holding, value_ahead, start, dq, found)
    moved = False
    for j in range(rows.size):
        if not (holding[owner[j]] and active[j]):
            continue
        shift = found[j] - coasting[j]
        lower[rows[j]] -= shift
        upper[rows[j]] -= shift
        moved = moved or shift != 0.0
    return moved


def _compile() -> None:
    """Compile the kernels (or load them from numba's cache) on empty arrays.

    Here, when an engine is made, rather than in its first control step.
    """
    A, rows, flags = np.zeros((0, 0)), np.zeros(0, dtype=np.intp), np.zeros(0, bool)
    x = np.zeros(0)
    _apply_coasting(A, 0, rows, rows, flags, x, x, x, x, x, flags, x)
    _holding(A, 0, rows, rows, flags, x, x, flags, x, flags)
    _refine_rows(A, 0, rows, rows, flags, x, x, x, x, flags, x, x)


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
