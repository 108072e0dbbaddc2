# SPDX-License-Identifier: Apache-2.0
"""QPAssembler: the QP of a fixed list of entries, in buffers allocated once.

Each plugin's rows are copied into preallocated blocks (:class:`_Block`), cut
from one float buffer (:class:`_Arena`), and one compiled pass
(:func:`~cbp.qp.kernel.fill_qp`) applies the weights, gains and bounds.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from cbp.errors import PluginOutputError
from cbp.plugin import AnyPlugin, Constraint, Task
from cbp.qp.kernel import (
    BOUNDS_NAN,
    COST_NOT_FINITE,
    ROW_KINDS,
    ROWS_NOT_FINITE,
    SIZES,
    fill_qp,
)
from cbp.qp.problem import Entry, QPProblem
from cbp.robot import FloatArray
from cbp.state import RobotState

__all__ = ["QPAssembler"]


class QPAssembler:
    r"""Builds the QP of a fixed list of entries, reusing its buffers every step.

    Row layout: one row per row of every hard task and constraint (hard tasks are
    equalities), then, for each row of a soft constraint, a second row for its
    upper side and a row keeping its slack non-negative. A soft constraint row i
    with slack :math:`s_i` reads :math:`l_i - s_i \le C_i \Delta q \le u_i + s_i`.

    Rows with infinite bounds stay in the problem (every backend accepts them), so
    the problem's shape never changes and no per-step mask is needed.

    The arrays of the returned :class:`QPProblem` are the assembler's own buffers:
    they hold until the next call to :meth:`assemble`; copy them to keep them.

    Args:
        entries: the task and constraint entries, in scenario order.
        nv: number of joint-displacement variables.
        regularization: :math:`\epsilon` added to the diagonal of H so the problem
            stays strictly convex when the soft terms leave directions free.
    """

    def __init__(
        self, entries: Sequence[Entry], nv: int, regularization: float = 1e-9
    ) -> None:
        """Lay out the row blocks of every entry and allocate the buffers."""
        self.entries = list(entries)
        self.nv = nv
        self.regularization = regularization
        self.entry_names = [e.name for e in self.entries]
        indexed = list(enumerate(self.entries))
        soft = [(i, e) for i, e in indexed if _is_soft_task(e)]
        # Soft tasks with a constant Jacobian: J^T W J joins H once, at the first
        # assembly, and each step only needs their values.
        constant = [(i, e) for i, e in soft if e.plugin.constant_jacobian]
        varying = [(i, e) for i, e in soft if not e.plugin.constant_jacobian]
        hard = [(i, e) for i, e in indexed if not _is_soft_task(e)]
        soft_rows = np.concatenate(
            [np.full(e.plugin.dim, e.priority == "soft") for _, e in hard]
            or [np.zeros(0, dtype=bool)]
        )
        self._slack_rows = np.flatnonzero(soft_rows)
        m_const = sum(e.plugin.dim for _, e in constant)
        m, ns = int(soft_rows.size), int(self._slack_rows.size)
        self.n = n = nv + ns
        rows = m + 2 * ns
        # Every float array the compiled pass reads or writes, in one buffer.
        arena = _Arena(
            sum(_Block.floats(b, nv) for b in (varying, constant, hard))
            + m_const * (nv + 1)
            + 2 * n * n
            + n
            + rows * (n + 2)
        )
        self._soft = _Block(varying, nv, arena)
        self._constant = _Block(constant, nv, arena)
        self._constant_JtW = arena.take((nv, m_const))  # set at the first step
        self._folded = False
        # The constant tasks' step -k f is formed by the compiled pass, unless a
        # task limits it (then in Python, by desired_change).
        folded, ones = self._constant, arena.take((m_const,), 1.0)
        self._constant_step = (
            (folded.desired, ones)
            if folded.limiting
            else (folded.f, folded.negative_gains)
        )
        block = _Block(hard, nv, arena)
        self._rows = block
        self._take_problem(arena, m, ns)
        self._floats = arena.full()
        self._layout = self._lay_out(arena, m_const)
        # Compile the pass, or load it from numba's cache, here rather than in the
        # first control step; on the zero buffers it writes the initial problem.
        self._fill()

    def _take_problem(self, arena: _Arena, m: int, ns: int) -> None:
        """The problem's arrays, cut from ``arena``, with what never changes set.

        H with the slacks' weights and the regularization on its diagonal, g,
        A with the slacks' columns, and the bounds (``m`` rows, ``ns``
        slacks).
        """
        nv, n, block = self.nv, self.n, self._rows
        rows = m + 2 * ns
        self._H_base = arena.take((n, n))
        self._H_base[nv:, nv:] = np.diag(block.weights[self._slack_rows])
        self._H_base[np.diag_indices(n)] += self.regularization
        self._H = arena.take((n, n))
        self._H[...] = self._H_base
        self._g = arena.take((n,))
        self._A = arena.take((rows, n))
        slack = np.arange(ns)
        self._A[self._slack_rows, nv + slack] = 1.0  # lower side: C dq + s >= l
        self._A[m + slack, nv + slack] = -1.0  # upper side: C dq - s <= u
        self._A[m + ns + slack, nv + slack] = 1.0  # s >= 0
        self._lower = arena.take((rows,), -np.inf)
        self._upper = arena.take((rows,), np.inf)
        self._lower[m + ns :] = 0.0
        self._row_entry = np.concatenate(
            [block.row_entry] + [block.row_entry[self._slack_rows]] * 2
        )
        self._problem = QPProblem(
            H=self._H,
            g=self._g,
            A=self._A,
            lower=self._lower,
            upper=self._upper,
            equality=np.zeros(rows, dtype=bool),
            row_entry=self._row_entry,
            entry_names=self.entry_names,
            nv=nv,
        )

    def _lay_out(self, arena: _Arena, m_const: int) -> npt.NDArray[np.int64]:
        """The layout :func:`~cbp.qp.kernel.fill_qp` reads.

        The sizes, where each float array lies in the buffer, then the
        integer arrays (the task rows, the slack rows).
        """
        block = self._rows
        constant_step, constant_scale = self._constant_step
        in_order = (
            self._H_base,
            self._H,
            self._g,
            self._soft.J,
            self._soft.weights,
            self._soft.desired,
            self._constant_JtW,
            constant_step,
            constant_scale,
            block.J,
            block.f,
            block.lower,
            block.upper,
            block.gains,
            block.desired,
            self._A,
            self._lower,
            self._upper,
        )
        ns = int(self._slack_rows.size)
        sizes = [self.nv, self.n, self._soft.m, m_const, block.m, ns]
        assert len(sizes) == SIZES
        assert len(in_order) == ROW_KINDS - SIZES
        layout: npt.NDArray[np.int64] = np.concatenate(
            [
                sizes,
                [arena.offset(a) for a in in_order],
                block.task_rows,
                self._slack_rows,
            ]
        ).astype(np.int64)
        return layout

    @property
    def values(self) -> FloatArray:
        """The values f of the hard entries' and soft constraints' rows, as assembled.

        In the problem's row order (its first rows); the assembler's buffer.
        """
        return self._rows.f

    def assemble(self, state: RobotState) -> QPProblem:
        """Linearize every entry at ``state`` and return the QP (shared buffers).

        The plugins are called from Python, block by block; the arithmetic that
        turns their outputs into H, g, A and the bounds is one compiled pass
        (:func:`fill_qp`), which also checks every output for NaN and inf.
        """
        soft, constant, block = self._soft, self._constant, self._rows
        if constant.m:
            if not self._folded:
                self._fold_constant(state)
            constant.fill(state)
            if constant.limiting:
                constant.desired_change()
        if soft.m:
            soft.fill(state)
            soft.desired_change()
        if block.m:
            block.fill(state)
            block.collect_bounds(state)
            if block.has_tasks:
                block.desired_change()
        status = self._fill()
        if status:
            self._raise(status)
        return self._problem

    def _fill(self) -> int:
        """Run :func:`fill_qp` on the blocks' current outputs; return its status."""
        return int(fill_qp(self._floats, self._layout, self._problem.equality))

    def _raise(self, status: int) -> None:
        """Name the entry behind a non-finite output that :func:`fill_qp` found."""
        if status & COST_NOT_FINITE:
            self._soft.raise_non_finite()
            self._constant.raise_non_finite()
        if status & ROWS_NOT_FINITE:
            self._rows.raise_non_finite()
        if status & BOUNDS_NAN:
            self._rows.raise_bad_bounds()
        # Finite outputs, yet a non-finite step asked for: a task's limit_step.
        raise PluginOutputError(
            "the step asked for by a task's limit_step is not finite: "
            + ", ".join(
                f"{task.name} ({task.type_name})"
                for b in (self._soft, self._constant, self._rows)
                for _, task in b.limiting
            )
        )

    def _fold_constant(self, state: RobotState) -> None:
        """Add the constant soft tasks' J^T W J to H's base, keep J^T W for g."""
        constant, nv = self._constant, self.nv
        constant.fill(state)
        JtW = self._constant_JtW
        JtW[...] = (constant.J * constant.weights[:, None]).T
        self._H_base[:nv, :nv] += JtW.dot(constant.J)
        self._H[:nv, :nv] = self._H_base[:nv, :nv]
        self._folded = True


class _Arena:
    """One float buffer cut into arrays, so that the compiled pass takes one array.

    Args:
        size: how many floats the arrays take in all.
    """

    def __init__(self, size: int) -> None:
        self._buffer = np.zeros(size)
        self._used = 0

    def take(self, shape: tuple[int, ...], fill: float = 0.0) -> FloatArray:
        """The next ``shape`` floats of the buffer (a view), set to ``fill``."""
        count = math.prod(shape)
        start, self._used = self._used, self._used + count
        if self._used > self._buffer.size:
            raise AssertionError(f"QP buffers: {self._used} > {self._buffer.size}")
        view = self._buffer[start : self._used].reshape(shape)
        view[...] = fill
        return view

    def offset(self, view: FloatArray) -> int:
        """Where ``view`` (taken from this buffer) starts in it."""
        return (view.ctypes.data - self._buffer.ctypes.data) // view.itemsize

    def full(self) -> FloatArray:
        """The buffer, once every array is taken."""
        if self._used != self._buffer.size:
            raise AssertionError(f"QP buffers: {self._used} of {self._buffer.size}")
        return self._buffer


def _is_soft_task(entry: Entry) -> bool:
    return isinstance(entry.plugin, Task) and entry.priority == "soft"


def _limits_step(task: Task[Any]) -> bool:
    """Whether a task limits its step (overrides either of Task's two calls)."""
    kind = type(task)
    return (
        kind.limit_step is not Task.limit_step
        or kind.limit_step_into is not Task.limit_step_into
    )


class _Block:
    """Preallocated rows of a group of entries: stacked values, Jacobians, weights.

    Its float arrays are cut from the assembler's buffer (:class:`_Arena`).
    """

    def __init__(
        self, entries: Sequence[tuple[int, Entry]], nv: int, arena: _Arena
    ) -> None:
        self.entries = [e for _, e in entries]
        dims = [e.plugin.dim for e in self.entries]
        self.m = m = int(sum(dims))
        self.nv = nv
        self.J = arena.take((m, nv))
        self.f = arena.take((m,))
        self.lower = arena.take((m,), -np.inf)
        self.upper = arena.take((m,), np.inf)
        starts = np.concatenate([[0], np.cumsum(dims)]).astype(int)
        self.slices = [slice(int(a), int(b)) for a, b in itertools.pairwise(starts)]
        self.items = [
            (sl, e.plugin) for sl, e in zip(self.slices, self.entries, strict=True)
        ]
        # Each plugin with its rows of the buffers (views, made once).
        self._rows = [(p, self.f[sl], self.J[sl]) for sl, p in self.items]
        # The first fill linearizes every entry; later ones only the entries
        # whose Jacobian varies, and evaluate the others' values.
        self._linearized = list(self._rows)
        self._constant_items = [(p, v) for p, v, _ in self._rows if p.constant_jacobian]
        self._evaluated: list[tuple[AnyPlugin, FloatArray]] = []
        self.row_entry = np.concatenate(
            [np.full(d, i) for (i, _), d in zip(entries, dims, strict=True)]
            or [np.zeros(0)]
        ).astype(np.intp)
        self.weights = arena.take((m,))
        self.gains = arena.take((m,))
        for sl, e in zip(self.slices, self.entries, strict=True):
            self.weights[sl] = e.weight
            self.gains[sl] = e.gain
        self.negative_gains = arena.take((m,))
        np.negative(self.gains, out=self.negative_gains)
        self.desired = arena.take((m,))
        self.limiting: list[tuple[slice, Task[Any]]] = [
            (sl, p) for sl, p in self.items if isinstance(p, Task) and _limits_step(p)
        ]
        # The limiting tasks with their rows of ``desired`` (views, made once).
        self._limited = [(task, self.desired[sl]) for sl, task in self.limiting]
        self.task_rows = np.concatenate(
            [
                np.full(d, isinstance(e.plugin, Task))
                for e, d in zip(self.entries, dims, strict=True)
            ]
            or [np.zeros(0, dtype=bool)]
        )
        self.has_tasks = bool(self.task_rows.any())
        self.constraints: list[tuple[slice, Constraint[Any]]] = [
            (sl, p) for sl, p in self.items if isinstance(p, Constraint)
        ]
        # The constraints with their rows of ``lower`` and ``upper`` (views).
        self._bounded = [
            (p, self.lower[sl], self.upper[sl]) for sl, p in self.constraints
        ]
        # Per constraint: the fixed bounds it returned last (see collect_bounds).
        self._kept_bounds: list[tuple[object, object]] = [(None, None)] * len(
            self._bounded
        )

    @staticmethod
    def floats(entries: Sequence[tuple[int, Entry]], nv: int) -> int:
        """How many floats a block of ``entries`` takes from the arena."""
        m = sum(e.plugin.dim for _, e in entries)
        return m * (nv + 7)

    def fill(self, state: RobotState) -> None:
        """Linearize every entry into its rows of the stacked buffers.

        Entries that declare ``constant_jacobian`` are linearized at the first
        call only; later calls evaluate their values and keep their Jacobian rows.
        """
        for plugin, value, jacobian in self._linearized:
            plugin.linearize_into(state, value, jacobian)
        for plugin, value in self._evaluated:
            plugin.value_into(state, value)
        if self._evaluated is not self._constant_items:
            self._linearized = [
                (p, v, J) for p, v, J in self._rows if not p.constant_jacobian
            ]
            self._evaluated = self._constant_items

    def raise_non_finite(self) -> None:
        """Raise PluginOutputError naming the first entry with a NaN or inf output."""
        for sl, plugin in self.items:
            if not (np.isfinite(self.f[sl]).all() and np.isfinite(self.J[sl]).all()):
                raise PluginOutputError(
                    f"{plugin.name} ({plugin.type_name}): value or Jacobian is not "
                    f"finite: value={self.f[sl]}"
                )

    def desired_change(self) -> None:
        """Write -k f of every row, after the tasks' step limits, into ``desired``."""
        np.multiply(self.f, self.negative_gains, out=self.desired)
        for task, rows in self._limited:
            task.limit_step_into(rows)

    def collect_bounds(self, state: RobotState) -> None:
        """Write every constraint's (lower, upper) on f into ``lower`` and ``upper``.

        Bounds returned as the same read-only arrays that own their data as
        at the last call (a constraint's fixed limits) are in place already
        and not copied again.
        """
        kept = self._kept_bounds
        for k, (plugin, given_lower, given_upper) in enumerate(self._bounded):
            lo, up = plugin.compute_bounds(state)
            last_lo, last_up = kept[k]
            if lo is last_lo and up is last_up:
                continue
            try:
                given_lower[:] = lo
                given_upper[:] = up
            except ValueError:
                raise PluginOutputError(
                    f"{plugin.name} ({plugin.type_name}): bounds have shapes "
                    f"{np.shape(lo)} and {np.shape(up)}, expected ({plugin.dim},)"
                ) from None
            kept[k] = (lo, up) if _fixed(lo) and _fixed(up) else (None, None)

    def raise_bad_bounds(self) -> None:
        """Raise PluginOutputError naming the first entry with NaN or crossed bounds."""
        for sl, plugin in self.constraints:
            lo, up = self.lower[sl], self.upper[sl]
            if not (lo <= up).all():
                raise PluginOutputError(
                    f"{plugin.name} ({plugin.type_name}): bounds must satisfy "
                    f"lower <= upper and not be NaN; got lower={lo}, upper={up}"
                )


def _fixed(bounds: object) -> bool:
    """Whether ``bounds`` is a read-only array that owns its data (cannot change)."""
    return (
        type(bounds) is np.ndarray
        and bounds.base is None
        and not bounds.flags.writeable
    )
