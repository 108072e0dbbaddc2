# SPDX-License-Identifier: Apache-2.0
"""QP backends, each called directly: daqp (default), piqp dense, cvxpy (reference).

On a 7-variable QP the layers between the engine and the solver cost more than the
solve itself (see ``benchmarks/RESULTS.md``), so every backend receives the engine's
dense arrays and calls its library directly. When a problem is infeasible, the
backend's status is not what the user sees: :func:`diagnose_infeasibility` solves a
relaxed copy with one slack per hard row and names the entries whose rows had to
give way.
"""

from __future__ import annotations

import abc
import contextlib
from collections.abc import Callable
from typing import Any, ClassVar

import numba
import numpy as np
import numpy.typing as npt

from cbp.errors import ConfigError, SolveError, suggestion
from cbp.qp import QPProblem
from cbp.robot import FloatArray

_INFEASIBLE_HINT = "the hard entries cannot all be met"


class QPSolver(abc.ABC):
    """A QP backend: solves a :class:`~cbp.qp.QPProblem` or raises SolveError."""

    name: ClassVar[str]

    @abc.abstractmethod
    def solve(self, problem: QPProblem) -> FloatArray:
        """Return the minimizer x (n,).

        Raises:
            SolveError: the problem is infeasible or the backend failed; the error
                names the conflicting entries when they can be found.
        """

    #: Whether an infeasible problem's error names the conflicting entries (a
    #: second, relaxed solve, several times the first's cost).
    diagnose: bool = True

    _trials: _Trials | None = None

    def trials(self) -> contextlib.AbstractContextManager[None]:
        """Solves whose failure is an answer, not an error: not diagnosed.

        The easing of an infeasible QP (:mod:`cbp.engine.recovery`) tries
        bounds until one solves; naming the conflicts of every failed try
        took a sixth of a CAT plan's time where obstacles pressed the arm.
        Every engine step solves within it: the context is one object per
        solver, made once (a generator's context took 1.5 us of a 24 us
        step).
        """
        trials = self._trials
        if trials is None:
            trials = self._trials = _Trials(self)
        return trials

    def _fail(self, problem: QPProblem, status: str, infeasible: bool) -> SolveError:
        diagnose = infeasible and self.diagnose
        conflicting = diagnose_infeasibility(problem) if diagnose else []
        return self._error(problem, status, infeasible, conflicting)

    def explained(self, error: SolveError) -> SolveError:
        """``error`` naming the conflicting entries, if a trial left them out.

        For a solve tried within :meth:`trials` whose failure turned out to
        be the answer after all: the diagnosis runs once, on the problem as
        the error holds it.
        """
        if error.conflicting or not error.infeasible or error.problem is None:
            return error
        conflicting = diagnose_infeasibility(error.problem)
        return self._error(error.problem, error.status, True, conflicting)

    def _error(
        self,
        problem: QPProblem,
        status: str,
        infeasible: bool,
        conflicting: list[str],
    ) -> SolveError:
        what = _INFEASIBLE_HINT if infeasible else "the solver failed"
        names = f": {', '.join(conflicting)}" if conflicting else ""
        return SolveError(
            f"{self.name}: {what}{names} (solver status: {status})",
            problem=problem,
            status=status,
            conflicting=conflicting,
            infeasible=infeasible,
        )


class _Trials:
    """:meth:`QPSolver.trials` of one solver: diagnosis off inside, nestable."""

    __slots__ = ("_before", "_solver")

    def __init__(self, solver: QPSolver) -> None:
        self._solver = solver
        self._before: list[bool] = []

    def __enter__(self) -> None:
        self._before.append(self._solver.diagnose)
        self._solver.diagnose = False

    def __exit__(self, *exc: object) -> None:
        self._solver.diagnose = self._before.pop()


class DaqpSolver(QPSolver):
    """daqp, a dual active-set method: exact on small dense problems, and fastest.

    Args:
        primal_tol: primal feasibility tolerance.
        iter_limit: iteration limit.
    """

    name = "daqp"

    def __init__(self, primal_tol: float = 1e-9, iter_limit: int = 1000) -> None:
        """Store the settings passed to daqp on every call."""
        import daqp

        self._solve = daqp.solve
        self._sense = np.zeros(0, dtype=np.int32)  # row flags: 5 = equality
        self.settings = {"primal_tol": primal_tol, "iter_limit": iter_limit}

    def solve(self, problem: QPProblem) -> FloatArray:
        """Solve with equality rows flagged to daqp (sense 5)."""
        sense, equality = self._sense, problem.equality
        if sense.shape != equality.shape:
            sense = self._sense = np.zeros(equality.shape, dtype=np.int32)
        _daqp_sense(equality, sense)
        # daqp factorizes H in its own copy; the engine's arrays stay untouched.
        x, _, exitflag, _ = self._solve(
            problem.H,
            problem.g,
            problem.A,
            problem.upper,
            problem.lower,
            sense,
            **self.settings,
        )
        if exitflag < 1:
            raise self._fail(problem, f"exitflag {exitflag}", infeasible=exitflag == -1)
        return np.asarray(x, dtype=float)


class PiqpSolver(QPSolver):
    """piqp's dense interior-point solver, with tolerances tight enough for small steps.

    Its default tolerances leave errors of ~3e-4 rad on 0.02 rad steps on this
    problem, so the defaults here are 1e-9.

    Args:
        eps_abs: absolute tolerance.
        eps_rel: relative tolerance.
        max_iter: iteration limit.
    """

    name = "piqp"

    def __init__(
        self, eps_abs: float = 1e-9, eps_rel: float = 1e-9, max_iter: int = 250
    ) -> None:
        """Keep the settings; a solver object is made per problem shape."""
        import piqp

        self._piqp = piqp
        self.eps_abs = eps_abs
        self.eps_rel = eps_rel
        self.max_iter = max_iter

    def solve(self, problem: QPProblem) -> FloatArray:
        """Split rows into equalities and two-sided inequalities and solve."""
        piqp = self._piqp
        eq = problem.equality
        solver = piqp.DenseSolver()
        solver.settings.eps_abs = self.eps_abs
        solver.settings.eps_rel = self.eps_rel
        solver.settings.max_iter = self.max_iter
        A = np.asfortranarray(problem.A[eq])
        G = np.asfortranarray(problem.A[~eq])
        solver.setup(
            np.asfortranarray(problem.H),
            problem.g,
            A if A.shape[0] else None,
            problem.lower[eq] if A.shape[0] else None,
            G if G.shape[0] else None,
            problem.lower[~eq] if G.shape[0] else None,
            problem.upper[~eq] if G.shape[0] else None,
        )
        status = solver.solve()
        if status != piqp.PIQP_SOLVED:
            infeasible = status in (
                piqp.PIQP_PRIMAL_INFEASIBLE,
                piqp.PIQP_DUAL_INFEASIBLE,
            )
            raise self._fail(problem, str(status), infeasible=infeasible)
        return np.array(solver.result.x, dtype=float)


class CvxpySolver(QPSolver):
    """cvxpy: the modelling-layer reference, ~100x slower than daqp; never the hot path.

    The problem is compiled once per shape with parameters (DPP) and then only
    re-solved.

    Args:
        solver: the cvxpy solver to call (default CLARABEL, installed with cvxpy).
        eps: tolerance passed to that solver.
    """

    name = "cvxpy"

    def __init__(self, solver: str = "CLARABEL", eps: float = 1e-9) -> None:
        """Keep the settings; problems are compiled lazily per shape."""
        import cvxpy

        self._cp = cvxpy
        self.solver = solver
        self.eps = eps
        self._cache: dict[tuple[int, ...], tuple[Any, ...]] = {}

    def _compiled(self, n: int, m_eq: int, m_lo: int, m_up: int) -> tuple[Any, ...]:
        key = (n, m_eq, m_lo, m_up)
        if key not in self._cache:
            cp = self._cp
            x = cp.Variable(n)
            L = cp.Parameter((n, n))
            g = cp.Parameter(n)
            A_eq, b_eq = cp.Parameter((m_eq, n)), cp.Parameter(m_eq)
            G_lo, lo = cp.Parameter((m_lo, n)), cp.Parameter(m_lo)
            G_up, up = cp.Parameter((m_up, n)), cp.Parameter(m_up)
            constraints = []
            if m_eq:
                constraints.append(A_eq @ x == b_eq)
            if m_lo:
                constraints.append(G_lo @ x >= lo)
            if m_up:
                constraints.append(G_up @ x <= up)
            objective = cp.Minimize(0.5 * cp.sum_squares(L @ x) + g @ x)
            problem = cp.Problem(objective, constraints)
            self._cache[key] = (problem, x, L, g, A_eq, b_eq, G_lo, lo, G_up, up)
        return self._cache[key]

    def solve(self, problem: QPProblem) -> FloatArray:
        """Factor H = L^T L and solve the compiled problem (finite bounds only)."""
        eq = problem.equality
        has_lo = ~eq & np.isfinite(problem.lower)
        has_up = ~eq & np.isfinite(problem.upper)
        compiled = self._compiled(
            problem.n, int(eq.sum()), int(has_lo.sum()), int(has_up.sum())
        )
        prob, x, L, g, A_eq, b_eq, G_lo, lo, G_up, up = compiled
        L.value = np.linalg.cholesky(problem.H).T
        g.value = problem.g
        A_eq.value, b_eq.value = problem.A[eq], problem.lower[eq]
        G_lo.value, lo.value = problem.A[has_lo], problem.lower[has_lo]
        G_up.value, up.value = problem.A[has_up], problem.upper[has_up]
        try:
            prob.solve(
                solver=self.solver,
                tol_gap_abs=self.eps,
                tol_gap_rel=self.eps,
                tol_feas=self.eps,
            )
        except self._cp.error.SolverError as exc:
            raise self._fail(problem, str(exc), infeasible=False) from exc
        status = str(prob.status)
        if status != "optimal":
            raise self._fail(problem, status, infeasible="infeasible" in status)
        return np.asarray(x.value, dtype=np.float64)


@numba.njit("void(boolean[:], int32[:])", cache=True, nogil=True)
def _daqp_sense(equality: npt.NDArray[np.bool_], sense: npt.NDArray[np.int32]) -> None:
    """The row flags daqp takes: 5 on an equality row, else 0.

    One compiled call (0.4 us on 14 rows) where numpy's cast and multiply
    took 0.8 us; one signature, compiled at import.
    """
    for i in range(equality.size):
        sense[i] = 5 if equality[i] else 0


#: Backends by name; the first is the default.
SOLVERS: dict[str, Callable[[], QPSolver]] = {
    "daqp": DaqpSolver,
    "piqp": PiqpSolver,
    "cvxpy": CvxpySolver,
}


def make_solver(name: str) -> QPSolver:
    """Return a backend by name.

    Raises:
        ConfigError: the name is unknown; the message lists the backends.
    """
    try:
        factory = SOLVERS[name]
    except KeyError:
        raise ConfigError(
            f"unknown solver '{name}'{suggestion(name, SOLVERS)} "
            f"Available: {', '.join(SOLVERS)}."
        ) from None
    return factory()


def diagnose_infeasibility(problem: QPProblem, tol: float = 1e-7) -> list[str]:
    r"""Name the entries whose rows cannot all be met together.

    Solves the relaxed problem :math:`\min \frac12 x^T H x + g^T x + \frac{\rho}{2}
    \|s\|^2` with :math:`l - s \le A x \le u + s`, :math:`s \ge 0`, one slack per
    row, and a large :math:`\rho`. The entries whose rows needed a slack above
    ``tol`` are the ones in conflict.

    Returns:
        Entry names in scenario order; empty if the relaxed solve also fails.
    """
    import daqp

    m, n = problem.A.shape
    if m == 0:
        return []
    rho = 1e6
    H = np.zeros((n + m, n + m))
    H[:n, :n] = problem.H
    H[n:, n:] = rho * np.eye(m)
    g = np.concatenate([problem.g, np.zeros(m)])
    eye = np.eye(m)
    zeros = np.zeros((m, n))
    A = np.block([[problem.A, eye], [problem.A, -eye], [zeros, eye]])
    lower = np.concatenate([problem.lower, np.full(m, -np.inf), np.zeros(m)])
    upper = np.concatenate([np.full(m, np.inf), problem.upper, np.full(m, np.inf)])
    x, _, exitflag, _ = daqp.solve(
        H, g, A, upper, lower, np.zeros(3 * m, dtype=np.int32)
    )
    if exitflag < 1:
        return []
    slack = np.asarray(x[n:])
    rows = np.flatnonzero(slack > tol)
    owners = sorted(set(problem.row_entry[rows].tolist()))
    return [problem.entry_names[i] for i in owners]
