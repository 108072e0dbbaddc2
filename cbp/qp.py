# SPDX-License-Identifier: Apache-2.0
r"""Stacking plugin outputs into one dense QP, in buffers allocated once.

The problem handed to a solver is

.. math::

    \min_x \tfrac12 x^T H x + g^T x \quad \text{s.t.} \quad
    l \le A x \le u,

with equality rows marked where :math:`l = u`. The first ``nv`` entries of x are
the joint displacement :math:`\Delta q`; any further entries are the slacks of soft
constraints. Rows whose two bounds are infinite are dropped before the solver sees
them.

This module runs hundreds of times per command period, so it avoids per-step
allocation and per-step numpy calls: each plugin's rows are copied into
preallocated blocks, and one compiled pass (numba) applies the weights, feedback
gains and bounds to all rows and checks them for NaN. On the 7-joint reaching
step, that pass replaced some 25 numpy calls and cut the step from 45 to 30 us.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from typing import Any, Literal

import numba
import numpy as np
import numpy.typing as npt

from cbp.errors import ConfigError, PluginOutputError
from cbp.plugin import AnyPlugin, Constraint, Task
from cbp.robot import FloatArray, IntArray
from cbp.state import RobotState

Priority = Literal["soft", "hard"]
BoolArray = npt.NDArray[np.bool_]


@dataclasses.dataclass(frozen=True)
class Entry:
    r"""A plugin with the engine-level settings of its scenario entry.

    Attributes:
        plugin: the bound plugin.
        priority: ``soft`` (weighted objective term) or ``hard`` (QP constraint).
        weight: per-row weights of a soft entry, shape (dim,). For a soft task the
            cost is :math:`\sum_i w_i (J_i \Delta q + k f_i)^2`; for a soft
            constraint, :math:`\sum_i w_i s_i^2` over its slacks.
        gain: feedback gain k per step, in [0, 1].
    """

    plugin: AnyPlugin
    priority: Priority
    weight: FloatArray
    gain: float

    @classmethod
    def make(
        cls,
        plugin: AnyPlugin,
        *,
        priority: Priority | None = None,
        weight: float | Sequence[float] | FloatArray = 1.0,
        gain: float | None = None,
    ) -> Entry:
        """Check the settings against the plugin and build the entry.

        Defaults: tasks are soft and constraints hard; the gain is the plugin's
        ``default_gain``.

        Raises:
            ConfigError: with ``location`` naming the bad setting.
        """
        if priority is None:
            priority = "soft" if isinstance(plugin, Task) else "hard"
        if priority not in ("soft", "hard"):
            raise ConfigError(
                f"priority '{priority}' is not one of soft, hard", location="priority"
            )
        dim = plugin.dim
        w = np.array(weight, dtype=float).reshape(-1)
        if w.size == 1:
            w = np.full(dim, float(w[0]))
        elif w.size != dim:
            raise ConfigError(
                f"weight has {w.size} entries, expected 1 or {dim} "
                f"(dim of {plugin.type_name})",
                location="weight",
            )
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ConfigError(
                f"weight must be finite and >= 0, got {w.tolist()}", location="weight"
            )
        k = plugin.default_gain if gain is None else float(gain)
        if not (0.0 <= k <= 1.0):
            raise ConfigError(
                f"gain {k} is outside [0, 1] (the fraction of the error removed "
                "per step)",
                location="gain",
            )
        w.flags.writeable = False
        return cls(plugin, priority, w, k)

    @property
    def name(self) -> str:
        """The plugin instance's name."""
        return self.plugin.name


@dataclasses.dataclass
class QPProblem:
    r"""One assembled QP: :math:`\min \frac12 x^T H x + g^T x`, :math:`l \le Ax \le u`.

    Attributes:
        H: cost matrix (n, n), symmetric positive definite.
        g: cost vector (n,).
        A: constraint rows (m, n).
        lower: lower bounds (m,), -inf allowed.
        upper: upper bounds (m,), +inf allowed.
        equality: mask (m,) of rows with lower == upper.
        row_entry: index of the entry each row came from (m,).
        entry_names: names of the entries, indexed by ``row_entry``.
        nv: number of joint-displacement variables (the first nv of x).
    """

    H: FloatArray
    g: FloatArray
    A: FloatArray
    lower: FloatArray
    upper: FloatArray
    equality: BoolArray
    row_entry: IntArray
    entry_names: list[str]
    nv: int

    @property
    def n(self) -> int:
        """Number of variables."""
        return int(self.H.shape[0])

    def cost(self, x: FloatArray) -> float:
        """Objective value at ``x``."""
        return float(0.5 * x.dot(self.H).dot(x) + self.g.dot(x))

    def violation(self, x: FloatArray) -> float:
        """Largest bound violation of the rows at ``x`` (0 when feasible)."""
        if self.A.shape[0] == 0:
            return 0.0
        Ax = self.A.dot(x)
        return float(max(np.max(self.lower - Ax), np.max(Ax - self.upper), 0.0))

    def active_entries(self, dq: FloatArray, tolerance: float = 1e-6) -> set[str]:
        """Names of the entries with a row at one of its bounds at step ``dq``.

        ``dq`` is the joint displacement (the first ``nv`` variables); a row is
        active within ``tolerance`` (absolute, plus relative to the bound).
        """
        if self.A.shape[0] == 0:
            return set()
        Ax = self.A[:, : self.nv].dot(dq)
        with np.errstate(invalid="ignore"):
            low = np.isfinite(self.lower) & (
                np.abs(Ax - self.lower) <= tolerance * (1.0 + np.abs(self.lower))
            )
            high = np.isfinite(self.upper) & (
                np.abs(self.upper - Ax) <= tolerance * (1.0 + np.abs(self.upper))
            )
        rows = np.flatnonzero(low | high)
        return {self.entry_names[i] for i in self.row_entry[rows].tolist()}


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
        self._H_base = arena.take((n, n))
        self._H_base[nv:, nv:] = np.diag(block.weights[self._slack_rows])
        self._H_base[np.diag_indices(n)] += regularization
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
        self._floats = arena.full()
        # Where the compiled pass finds its arrays in that buffer, and the
        # integer arrays it reads (see fill_qp).
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
        sizes = [nv, n, self._soft.m, m_const, m, ns]
        assert len(sizes) == _SIZES
        assert len(in_order) == _ROW_KINDS - _SIZES
        self._layout = np.concatenate(
            [
                sizes,
                [arena.offset(a) for a in in_order],
                block.task_rows,
                self._slack_rows,
            ]
        ).astype(np.int64)
        # Compile the pass, or load it from numba's cache, here rather than in the
        # first control step; on the zero buffers it writes the initial problem.
        self._fill()

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
        if status & _COST_NOT_FINITE:
            self._soft.raise_non_finite()
            self._constant.raise_non_finite()
        if status & _ROWS_NOT_FINITE:
            self._rows.raise_non_finite()
        if status & _BOUNDS_NAN:
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


# The layout read by fill_qp: 6 sizes, then 18 offsets, then the rows' kinds.
_SIZES = 6
_ROW_KINDS = _SIZES + 18

# Bits of the status returned by fill_qp.
_COST_NOT_FINITE = 1
_ROWS_NOT_FINITE = 2
_BOUNDS_NAN = 4


@numba.njit(cache=True, nogil=True)
def fill_qp(floats: FloatArray, layout: IntArray, equality: BoolArray) -> int:
    r"""Turn the stacked plugin outputs into the QP, in place; return a status.

    The arrays are cut from two buffers made once per problem shape by
    :class:`QPAssembler`: ``floats`` holds every float array, ``layout`` the
    sizes (nv, n, soft rows, constant soft rows, rows m, slacks), the offset
    of each float array in ``floats`` (in :func:`_fill_arrays`'s order), then
    the task rows (m, 0 or 1) and the slack rows. Three arguments rather than
    twenty-two: numba's dispatch costs about 50 ns per array argument.
    See :func:`_fill_arrays` for what is computed.
    """
    nv, n, ms, mc = layout[0], layout[1], layout[2], layout[3]
    m, ns = layout[4], layout[5]
    at = layout[_SIZES:_ROW_KINDS]  # the float arrays' offsets
    rows = m + 2 * ns
    return _fill_arrays(
        nv,
        _cut(floats, at[0], n, n),
        _cut(floats, at[1], n, n),
        floats[at[2] : at[2] + n],
        _cut(floats, at[3], ms, nv),
        floats[at[4] : at[4] + ms],
        floats[at[5] : at[5] + ms],
        _cut(floats, at[6], nv, mc),
        floats[at[7] : at[7] + mc],
        floats[at[8] : at[8] + mc],
        _cut(floats, at[9], m, nv),
        floats[at[10] : at[10] + m],
        floats[at[11] : at[11] + m],
        floats[at[12] : at[12] + m],
        floats[at[13] : at[13] + m],
        layout[_ROW_KINDS : _ROW_KINDS + m],
        floats[at[14] : at[14] + m],
        layout[_ROW_KINDS + m : _ROW_KINDS + m + ns],
        _cut(floats, at[15], rows, n),
        floats[at[16] : at[16] + rows],
        floats[at[17] : at[17] + rows],
        equality,
    )


@numba.njit(cache=True, nogil=True, inline="always")
def _cut(floats: FloatArray, start: int, rows: int, cols: int) -> FloatArray:
    """The (rows, cols) matrix at ``start`` of the buffer (a view)."""
    return floats[start : start + rows * cols].reshape((rows, cols))


@numba.njit(cache=True, nogil=True)
def _fill_arrays(
    nv: int,
    H_base: FloatArray,
    H: FloatArray,
    g: FloatArray,
    soft_J: FloatArray,
    soft_weights: FloatArray,
    soft_desired: FloatArray,
    constant_JtW: FloatArray,
    constant_step: FloatArray,
    constant_scale: FloatArray,
    J: FloatArray,
    f: FloatArray,
    given_lower: FloatArray,
    given_upper: FloatArray,
    gains: FloatArray,
    task_rows: IntArray,
    desired: FloatArray,
    slack_rows: IntArray,
    A: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    equality: BoolArray,
) -> int:
    r"""The arithmetic of :func:`fill_qp`, on its arrays.

    Cost, over the joint block: :math:`H = H_0 + J_s^T W J_s` and
    :math:`g = -(J_s^T W d_s + (J_c^T W_c) d_c)`, with :math:`d = -k f` after the
    tasks' step limits (soft tasks s, constant-Jacobian soft tasks c, whose
    :math:`J_c^T W_c J_c` is already in :math:`H_0`); :math:`d_c` is
    ``constant_step * constant_scale``: f and -k, or (when a task there limits
    its step) the limited step and ones.

    Rows: A = J; a constraint row's bounds are :math:`k (l - f)` and
    :math:`k (u - f)`, except that an infinite bound stays infinite when k = 0;
    a hard task's are :math:`d` on both sides. Each soft constraint row's upper
    side moves to its own row (``slack_rows``, laid out by the assembler).

    The status is 0, or a sum of bits: ``_COST_NOT_FINITE`` (a soft task's
    Jacobian or step), ``_ROWS_NOT_FINITE`` (a row's value or Jacobian),
    ``_BOUNDS_NAN`` (a constraint's bound).
    """
    status = 0
    for a in range(nv):
        for b in range(nv):
            H[a, b] = H_base[a, b]
        g[a] = 0.0
    for i in range(soft_J.shape[0]):
        w, d = soft_weights[i], soft_desired[i]
        if not math.isfinite(d):
            status |= _COST_NOT_FINITE
        for a in range(nv):
            wa = w * soft_J[i, a]
            if not math.isfinite(wa):
                status |= _COST_NOT_FINITE
            g[a] -= wa * d
            for b in range(nv):
                H[a, b] += wa * soft_J[i, b]
    for i in range(constant_step.size):
        d = constant_step[i] * constant_scale[i]
        if not math.isfinite(d):
            status |= _COST_NOT_FINITE
        for a in range(nv):
            g[a] -= constant_JtW[a, i] * d
    m = f.size
    for r in range(m):
        if not math.isfinite(f[r]):
            status |= _ROWS_NOT_FINITE
        for c in range(nv):
            v = J[r, c]
            if not math.isfinite(v):
                status |= _ROWS_NOT_FINITE
            A[r, c] = v
        if task_rows[r]:
            lower[r] = upper[r] = desired[r]
            continue
        k, lo, up = gains[r], given_lower[r], given_upper[r]
        if math.isnan(lo) or math.isnan(up):
            status |= _BOUNDS_NAN
        lower[r] = lo if k == 0.0 and math.isinf(lo) else k * (lo - f[r])
        upper[r] = up if k == 0.0 and math.isinf(up) else k * (up - f[r])
    for j in range(slack_rows.size):
        r = slack_rows[j]
        for c in range(nv):
            A[m + j, c] = J[r, c]
        upper[m + j] = upper[r]
        upper[r] = math.inf
    for r in range(lower.size):
        equality[r] = lower[r] == upper[r]
    return status
