# SPDX-License-Identifier: Apache-2.0
"""Easing an infeasible QP: the hard rows that ask for motion, capped or scaled.

When hard rows ask for more motion than the others allow (the arm inside its
safety distance or in penetration, a joint past its limit), the step is solved
again with those demands eased (:func:`ease`), and the engine's result says
how (:class:`Easing`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cbp.errors import SolveError
from cbp.qp import QPProblem
from cbp.robot import FloatArray
from cbp.solvers import QPSolver

__all__ = ["Easing", "ease"]

#: A hard row's bound within this of zero does not count as asking for motion.
EASE_TOL = 1e-12

#: Bisection steps for the largest feasible scale of the demands (1/64).
SCALE_BISECTIONS = 6


@dataclass(frozen=True)
class Easing:
    """How a step's QP was eased to be solvable.

    Attributes:
        description: which rows asked for too much, and what was done.
        scale: the factor every demand was scaled by (0: held, "no further");
            None when the inequality demands were only capped (backing out).
    """

    description: str
    scale: float | None

    def __str__(self) -> str:
        """The description."""
        return self.description


def ease(
    problem: QPProblem,
    error: SolveError,
    dt: float,
    solver: QPSolver,
    easable: np.ndarray,
    v: FloatArray,
) -> tuple[FloatArray, Easing]:
    """Solve again with the hard rows that ask for motion eased; else re-raise.

    Args:
        problem: the infeasible QP; its bounds are left as the answer's.
        error: what the first solve raised (raised again when nothing helps).
        dt: the step's duration [s].
        solver: the backend.
        easable: per entry, whether its rows may be eased
            (:attr:`cbp.plugin.Plugin.easable`).
        v: the robot's velocity at the step's start (nv; zero at rest).

    A hard row whose bounds exclude standing still asks the step for a
    motion of its own: an inequality row inside its safety distance or a
    joint past its limit, an equality row with an error to remove. Several
    of them, or one beyond what the velocity and acceleration rows allow,
    can leave no feasible step. First each inequality demand is capped at
    half of what the single-joint rows (the velocity bounds) let that row
    reach: the arm backs out as fast as its limits allow. If that is still
    infeasible, every demand, equalities' included, is scaled by the
    largest factor in [0, 1) that the limits allow (bisection); at 0 the
    inequalities become "no further" (the k = 0 form) and the equalities
    ask for what the robot's present velocity (``v``) gives them, which
    its acceleration limits always allow. Rows of plugins that are physical
    limits (``easable = False``: ``joint_acceleration``) are never eased.

    Returns:
        The solution, and how the QP was eased.

    Raises:
        SolveError: ``error``, when no easing makes the QP solvable.
    """
    lower, upper = problem.lower, problem.upper
    nv = len(v)
    # Hard (no slack variable) rows of easable entries.
    hard = ~problem.A[:, nv:].any(axis=1) & easable[problem.row_entry]
    asks_up, asks_down = lower > EASE_TOL, upper < -EASE_TOL
    inequality = hard & ~problem.equality & (asks_up | asks_down)
    equality = hard & problem.equality & (asks_up | asks_down)
    rows = np.flatnonzero(inequality | equality)
    if rows.size == 0:
        raise error
    names = sorted({problem.entry_names[problem.row_entry[r]] for r in rows})
    what = (
        f"{len(rows)} row(s) of {', '.join(names)} asked for more motion than "
        "the limits allow together: "
    )
    given = (lower[rows].copy(), upper[rows].copy())
    if inequality.any():
        A = problem.A[:, :nv]
        reach_hi, reach_lo = _row_reach(A, lower, upper)
        capped = np.flatnonzero(inequality)
        lower[capped] = np.minimum(lower[capped], 0.5 * np.maximum(reach_hi[capped], 0))
        upper[capped] = np.maximum(upper[capped], 0.5 * np.minimum(reach_lo[capped], 0))
        try:
            x = solver.solve(problem)
        except SolveError:
            pass
        else:
            if not equality.any():
                backing = "eased to half of what the velocity bounds reach "
                return x, Easing(what + backing + "(backing out)", None)
        lower[rows], upper[rows] = given  # infeasible, or equalities to scale

    # An equality is scaled from the value its row has if the robot keeps
    # its velocity (the state's v; zero at rest), which the acceleration
    # rows always allow; an inequality from zero, "no further".
    equal = problem.equality[rows]
    anchor = np.zeros(rows.size)
    anchor[equal] = problem.A[rows[equal], :nv] @ (v * dt)

    def scale(factor: float) -> None:
        """Set every demand's bounds to ``factor`` of what it asks."""
        lo, hi = given
        lower[rows] = np.where(lo > anchor, anchor + factor * (lo - anchor), lo)
        upper[rows] = np.where(hi < anchor, anchor + factor * (hi - anchor), hi)
        lower[rows[equal]] = upper[rows[equal]] = anchor[equal] + factor * (
            lo[equal] - anchor[equal]
        )

    def scaled(factor: float) -> FloatArray | None:
        """The solution with every demand scaled by ``factor``, or None."""
        scale(factor)
        try:
            return solver.solve(problem)
        except SolveError:
            return None

    best = scaled(0.0)
    if best is None:
        lower[rows], upper[rows] = given
        raise error
    low, high = 0.0, 1.0
    for _ in range(SCALE_BISECTIONS):
        middle = 0.5 * (low + high)
        found = scaled(middle)
        if found is None:
            high = middle
        else:
            low, best = middle, found
    scale(low)  # leave the bounds of the answer in the problem
    if low == 0.0:
        return best, Easing(what + "held (k = 0: no further, no change)", low)
    return best, Easing(what + "scaled down to what the limits allow", low)


def _row_reach(
    A: FloatArray, lower: FloatArray, upper: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The largest and smallest value each row of ``A dq`` can take in the box.

    The box is what the single-variable rows (velocity bounds) allow each
    variable; a variable no such row bounds makes the reach infinite.
    """
    nonzero = A != 0.0
    single = np.flatnonzero(nonzero.sum(axis=1) == 1)
    lo = np.full(A.shape[1], -np.inf)
    hi = np.full(A.shape[1], np.inf)
    for r in single.tolist():
        i = int(np.flatnonzero(nonzero[r])[0])
        a = A[r, i]
        bounds = sorted((lower[r] / a, upper[r] / a))
        lo[i] = max(lo[i], bounds[0])
        hi[i] = min(hi[i], bounds[1])
    with np.errstate(invalid="ignore"):
        top = np.where(A > 0, A * hi, A * lo)
        bottom = np.where(A > 0, A * lo, A * hi)
    top[A == 0.0] = 0.0
    bottom[A == 0.0] = 0.0
    return top.sum(axis=1), bottom.sum(axis=1)
