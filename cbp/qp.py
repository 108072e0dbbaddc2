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
allocation where it can and keeps numpy calls per step few: each plugin's rows are
copied into preallocated blocks, and the weighting, feedback gains and bounds are
applied to all rows at once.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from typing import Any, Literal

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
        self._soft = _Block(varying, nv)
        self._constant = _Block(constant, nv)
        self._constant_JtW = np.zeros((0, 0))
        block = _Block([(i, e) for i, e in indexed if not _is_soft_task(e)], nv)
        self._rows = block
        soft_rows = np.concatenate(
            [np.full(e.plugin.dim, e.priority == "soft") for e in block.entries]
            or [np.zeros(0, dtype=bool)]
        )
        self._slack_rows = np.flatnonzero(soft_rows)
        m, ns = block.m, self._slack_rows.size
        self.n = n = nv + ns
        self._H_base = np.zeros((n, n))
        self._H_base[nv:, nv:] = np.diag(block.weights[self._slack_rows])
        self._H_base[np.diag_indices(n)] += regularization
        self._H = self._H_base.copy()
        self._g = np.zeros(n)
        self._A = np.zeros((m + 2 * ns, n))
        slack = np.arange(ns)
        self._A[self._slack_rows, nv + slack] = 1.0  # lower side: C dq + s >= l
        self._A[m + slack, nv + slack] = -1.0  # upper side: C dq - s <= u
        self._A[m + ns + slack, nv + slack] = 1.0  # s >= 0
        self._lower = np.full(m + 2 * ns, -np.inf)
        self._upper = np.full(m + 2 * ns, np.inf)
        self._lower[m + ns :] = 0.0
        self._row_entry = np.concatenate(
            [block.row_entry] + [block.row_entry[self._slack_rows]] * 2
        )
        self._ones_nv = np.ones(nv)
        self._ones_m = np.ones(m)
        self._problem = QPProblem(
            H=self._H,
            g=self._g,
            A=self._A,
            lower=self._lower,
            upper=self._upper,
            equality=np.zeros(m + 2 * ns, dtype=bool),
            row_entry=self._row_entry,
            entry_names=self.entry_names,
            nv=nv,
        )

    def assemble(self, state: RobotState) -> QPProblem:
        """Linearize every entry at ``state`` and return the QP (shared buffers)."""
        nv = self.nv
        H, g = self._H, self._g
        soft, constant = self._soft, self._constant
        if constant.m:
            if not self._constant_JtW.size:
                self._fold_constant(state)
            constant.fill(state)
            g[:nv] = self._constant_JtW.dot(constant.desired_change())
        if soft.m:
            soft.fill(state)
            Jw = soft.J * soft.sqrt_weights[:, None]
            np.add(self._H_base[:nv, :nv], Jw.T.dot(Jw), out=H[:nv, :nv])
            if constant.m:
                g[:nv] += Jw.T.dot(soft.desired_change() * soft.sqrt_weights)
            else:
                g[:nv] = Jw.T.dot(soft.desired_change() * soft.sqrt_weights)
        if soft.m or constant.m:
            np.negative(g, out=g)
        block = self._rows
        m = block.m
        problem = self._problem
        if m:
            block.fill(state)
            A, lower, upper = self._A, self._lower, self._upper
            A[:m, :nv] = block.J
            block.row_bounds(state, lower[:m], upper[:m])
            k = self._slack_rows
            if k.size:
                ns = k.size
                A[m : m + ns, :nv] = block.J[k]
                upper[m : m + ns] = upper[k]
                upper[k] = np.inf
            np.equal(lower, upper, out=problem.equality)
            # NaN anywhere in f, J or the bounds shows up in these sums (an infinite
            # bound squares to +inf, never NaN); a misordered pair makes the QP
            # infeasible, which the solver layer reports.
            if math.isnan(lower.dot(lower) + upper.dot(upper)) or not math.isfinite(
                self._ones_m.dot(block.J.dot(self._ones_nv))
            ):
                block.raise_non_finite()
                block.raise_bad_bounds()
        if (soft.m or constant.m) and not math.isfinite(g.dot(g)):
            soft.raise_non_finite()
            constant.raise_non_finite()
        return problem

    def _fold_constant(self, state: RobotState) -> None:
        """Add the constant soft tasks' J^T W J to H's base, keep J^T W for g."""
        constant, nv = self._constant, self.nv
        constant.fill(state)
        JtW = (constant.J * constant.weights[:, None]).T.copy()
        self._H_base[:nv, :nv] += JtW.dot(constant.J)
        self._H[:nv, :nv] = self._H_base[:nv, :nv]
        self._constant_JtW = JtW


def _is_soft_task(entry: Entry) -> bool:
    return isinstance(entry.plugin, Task) and entry.priority == "soft"


class _Block:
    """Preallocated rows of a group of entries: stacked values, Jacobians, weights."""

    def __init__(self, entries: Sequence[tuple[int, Entry]], nv: int) -> None:
        self.entries = [e for _, e in entries]
        dims = [e.plugin.dim for e in self.entries]
        self.m = int(sum(dims))
        self.nv = nv
        self.J = np.zeros((self.m, nv))
        self.f = np.zeros(self.m)
        self.lower = np.full(self.m, -np.inf)
        self.upper = np.full(self.m, np.inf)
        starts = np.concatenate([[0], np.cumsum(dims)]).astype(int)
        self.slices = [slice(int(a), int(b)) for a, b in itertools.pairwise(starts)]
        self.items = [
            (sl, e.plugin, ((d,), (d, nv)))
            for sl, e, d in zip(self.slices, self.entries, dims, strict=True)
        ]
        # The first fill linearizes every entry; later ones only the entries
        # whose Jacobian varies, and evaluate the others' values.
        self._linearized = list(self.items)
        self._constant_items = [it for it in self.items if it[1].constant_jacobian]
        self._evaluated: list[tuple[slice, AnyPlugin, tuple[Any, Any]]] = []
        self.row_entry = np.concatenate(
            [np.full(d, i) for (i, _), d in zip(entries, dims, strict=True)]
            or [np.zeros(0)]
        ).astype(np.intp)
        self.weights = np.concatenate([e.weight for e in self.entries] or [np.zeros(0)])
        self.sqrt_weights = np.sqrt(self.weights)
        self.gains = np.concatenate(
            [np.full(d, e.gain) for e, d in zip(self.entries, dims, strict=True)]
            or [np.zeros(0)]
        )
        # Rows whose gain is 0: there k (l - f) must stay -inf when l is.
        self.zero_gain = self.gains == 0.0
        self.has_zero_gain = bool(self.zero_gain.any())
        self.limiting: list[tuple[slice, Task[Any]]] = [
            (sl, p)
            for sl, p, _ in self.items
            if isinstance(p, Task) and type(p).limit_step is not Task.limit_step
        ]
        self.task_rows = np.concatenate(
            [
                np.full(d, isinstance(e.plugin, Task))
                for e, d in zip(self.entries, dims, strict=True)
            ]
            or [np.zeros(0, dtype=bool)]
        )
        self.has_tasks = bool(self.task_rows.any())
        self.constraints: list[tuple[slice, Constraint[Any]]] = [
            (sl, p) for sl, p, _ in self.items if isinstance(p, Constraint)
        ]

    def fill(self, state: RobotState) -> None:
        """Linearize every entry into the stacked buffers, checking shapes.

        Entries that declare ``constant_jacobian`` are linearized at the first
        call only; later calls evaluate their values and keep their Jacobian rows.
        """
        f, J = self.f, self.J
        for sl, plugin, shapes in self._linearized:
            value, jac = plugin.linearize(state)
            if (getattr(value, "shape", None), getattr(jac, "shape", None)) != shapes:
                raise PluginOutputError(
                    f"{plugin.name} ({plugin.type_name}): value has shape "
                    f"{np.shape(value)} and Jacobian {np.shape(jac)}, expected "
                    f"{shapes[0]} and {shapes[1]}"
                )
            f[sl] = value
            J[sl] = jac
        for sl, plugin, shapes in self._evaluated:
            value = plugin.compute_value(state)
            if getattr(value, "shape", None) != shapes[0]:
                raise PluginOutputError(
                    f"{plugin.name} ({plugin.type_name}): value has shape "
                    f"{np.shape(value)}, expected {shapes[0]}"
                )
            f[sl] = value
        if self._evaluated is not self._constant_items:
            self._linearized = [it for it in self.items if not it[1].constant_jacobian]
            self._evaluated = self._constant_items

    def raise_non_finite(self) -> None:
        """Raise PluginOutputError naming the first entry with a NaN or inf output."""
        for sl, plugin, _ in self.items:
            if not (np.isfinite(self.f[sl]).all() and np.isfinite(self.J[sl]).all()):
                raise PluginOutputError(
                    f"{plugin.name} ({plugin.type_name}): value or Jacobian is not "
                    f"finite: value={self.f[sl]}"
                )

    def desired_change(self) -> FloatArray:
        """Return -k f for every row, after each task's own step limit."""
        desired = self.gains * self.f
        np.negative(desired, out=desired)
        for sl, task in self.limiting:
            desired[sl] = task.limit_step(desired[sl])
        return desired  # type: ignore[no-any-return]

    def row_bounds(
        self, state: RobotState, lower: FloatArray, upper: FloatArray
    ) -> None:
        """Write the bounds on J dq of every row into ``lower`` and ``upper``.

        Constraints: l' = k (l - f), u' = k (u - f). Hard tasks: l' = u' = -k f.
        """
        given_lower, given_upper = self.lower, self.upper
        for sl, plugin in self.constraints:
            lo, up = plugin.compute_bounds(state)
            try:
                given_lower[sl] = lo
                given_upper[sl] = up
            except ValueError:
                raise PluginOutputError(
                    f"{plugin.name} ({plugin.type_name}): bounds have shapes "
                    f"{np.shape(lo)} and {np.shape(up)}, expected ({plugin.dim},)"
                ) from None
        np.subtract(given_lower, self.f, out=lower)
        np.subtract(given_upper, self.f, out=upper)
        if not self.has_zero_gain:
            lower *= self.gains
            upper *= self.gains
        else:  # 0 * inf is NaN: an infinite bound must stay infinite
            with np.errstate(invalid="ignore"):
                lower *= self.gains
                upper *= self.gains
            np.copyto(lower, given_lower, where=self.zero_gain & np.isinf(given_lower))
            np.copyto(upper, given_upper, where=self.zero_gain & np.isinf(given_upper))
        if self.has_tasks:
            desired = self.desired_change()
            rows = self.task_rows
            lower[rows] = desired[rows]
            upper[rows] = desired[rows]

    def raise_bad_bounds(self) -> None:
        """Raise PluginOutputError naming the first entry with NaN or crossed bounds."""
        for sl, plugin in self.constraints:
            lo, up = self.lower[sl], self.upper[sl]
            if not (lo <= up).all():
                raise PluginOutputError(
                    f"{plugin.name} ({plugin.type_name}): bounds must satisfy "
                    f"lower <= upper and not be NaN; got lower={lo}, upper={up}"
                )
