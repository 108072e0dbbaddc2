# SPDX-License-Identifier: Apache-2.0
"""What the QP is made of: entries (a plugin with its settings) and the problem."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Literal

import numpy as np
import numpy.typing as npt

from cbp.errors import ConfigError
from cbp.plugin import AnyPlugin, Task
from cbp.robot import FloatArray, IntArray

__all__ = ["BoolArray", "Entry", "Priority", "QPProblem"]

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
