# SPDX-License-Identifier: Apache-2.0
"""Easing an infeasible QP: the hard rows that ask for motion, capped or scaled.

When hard rows ask for more motion than the others allow (the arm inside its
safety distance or in penetration, a joint past its limit), the step is solved
again with those demands eased (:func:`ease`), and the engine's result says
how (:class:`Easing`). When the step also carries rows that no easing makes
true (the acceleration limits of a robot in motion), what cannot hold gives
way in a fixed order instead (:func:`give_way_levels`): the robot's velocity
and acceleration limits never, then its position limits, then the other
constraints (obstacles), then the tasks and equalities (the orbit's).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cbp.errors import SolveError
from cbp.plugin import AnyPlugin
from cbp.qp import QPProblem
from cbp.robot import FloatArray, IntArray
from cbp.solvers import QPSolver

__all__ = ["GIVE_WAY_ORDER", "Easing", "ease", "give_way_levels"]

#: A hard row's bound within this of zero does not count as asking for motion.
EASE_TOL = 1e-12

#: Bisection steps for the largest feasible scale of the demands (1/64).
SCALE_BISECTIONS = 6

#: What gives way, by level: level 0 (the robot's velocity and acceleration
#: limits) never; then each level in turn, as little as it must, before the
#: next one gives any way at all. Equality rows (tasks, the orbit's
#: distance and view) are the last level, whatever their entry.
GIVE_WAY_ORDER = (
    "velocity and acceleration limits",
    "position limits",
    "constraints",
    "tasks and equalities",
)

#: Give-way levels (:data:`GIVE_WAY_ORDER`).
LIMITS, POSITIONS, CONSTRAINTS, EQUALITIES = range(4)

#: A row gives way by its least violation plus this [its unit per step]: the
#: solver meets bounds to about 1e-9.
GIVE_WAY_TOL = 1e-8

#: The weight of the joint step against the violations while the least
#: violations of a level are found (it only makes that QP strictly convex).
GIVE_WAY_REGULARIZATION = 1e-6


@dataclass(frozen=True)
class Easing:
    """How a step's QP was eased to be solvable.

    Attributes:
        description: which rows asked for too much, and what was done.
        scale: the factor every demand was scaled by (0: held, "no further");
            None when the inequality demands were only capped (backing out),
            or when the rows gave way in order.
    """

    description: str
    scale: float | None

    def __str__(self) -> str:
        """The description."""
        return self.description


def give_way_levels(plugins: Sequence[AnyPlugin]) -> IntArray:
    """Per entry, when its hard inequality rows give way (:data:`GIVE_WAY_ORDER`).

    A physical limit no easing makes true (``easable = False``) and the
    velocity limits: never (0); the position limits: first (1); any other
    constraint (an obstacle, the altitude): next (2). A hard equality row
    gives way before any of them (3), whatever its entry.
    """
    return np.array(
        [
            LIMITS
            if not p.easable or p.robot_limit in ("velocity", "acceleration")
            else POSITIONS
            if p.robot_limit == "position"
            else CONSTRAINTS
            for p in plugins
        ],
        dtype=np.intp,
    )


def ease(
    problem: QPProblem,
    error: SolveError,
    dt: float,
    solver: QPSolver,
    easable: np.ndarray,
    v: FloatArray,
    levels: IntArray | None = None,
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
        levels: per entry, when its rows give way (:func:`give_way_levels`);
            by default from ``easable`` alone.

    A hard row whose bounds exclude standing still asks the step for a
    motion of its own: an inequality row inside its safety distance or a
    joint past its limit, an equality row with an error to remove. Several
    of them, or one beyond what the velocity and acceleration rows allow,
    can leave no feasible step. First each inequality demand is capped at
    half of what the single-joint rows (the velocity bounds) let that row
    reach: the arm backs out as fast as its limits allow. Inequality
    demands that conflict even so (obstacles on two sides) are scaled by one
    factor and met as nearly as they allow together
    (:func:`_nearest_to_demands`). With equality
    demands, or if that is still infeasible, every demand, equalities'
    included, is scaled by the
    largest factor in [0, 1) that the limits allow (bisection); at 0 the
    inequalities become "no further" (the k = 0 form) and the equalities
    ask for what the robot's present velocity (``v``) gives them, which
    its acceleration limits always allow. Rows of plugins that are physical
    limits (``easable = False``: ``joint_acceleration``) are never eased.

    When the QP has such rows, neither standing still nor keeping the present
    velocity need be within them (a joint braking before its position limit
    can do neither), and one scale for every demand can leave the QP
    infeasible, or scale down an obstacle's row for a task's sake; and a row
    that asks for no motion can still not hold (an obstacle approached faster
    than the robot can brake). Then, instead of the capping and the scaling,
    the rows give way in order
    (:func:`_give_way`): each level of :data:`GIVE_WAY_ORDER` by its least
    violation (sum of squares) that the levels before it allow, the later
    levels left free meanwhile; the step is then the QP's own optimum within
    the bounds so widened.

    Returns:
        The solution, and how the QP was eased.

    Raises:
        SolveError: ``error``, when no easing makes the QP solvable.

    Call it within ``solver.trials()``: its trial solves are expected to fail,
    and naming their conflicts would cost more than the solves.
    """
    if not easable[problem.row_entry].all():  # rows of physical limits
        return _give_way(
            problem,
            error,
            solver,
            np.where(easable, CONSTRAINTS, LIMITS) if levels is None else levels,
        )
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
        if not equality.any():
            nearest = _nearest_to_demands(
                problem, rows, given, (reach_hi[rows], reach_lo[rows]), solver
            )
            if nearest is not None:
                return nearest, Easing(what + NEAREST, None)
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
        # Only a demand is scaled: an infinite bound stays (and 0 x inf is
        # never formed).
        ask_lo, ask_hi = lo > anchor, hi < anchor
        lower[rows] = np.where(
            ask_lo, anchor + factor * (np.where(ask_lo, lo, anchor) - anchor), lo
        )
        upper[rows] = np.where(
            ask_hi, anchor + factor * (np.where(ask_hi, hi, anchor) - anchor), hi
        )
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


#: How an easing that met the demands as nearly as they allow together is
#: described (:func:`_nearest_to_demands`).
NEAREST = (
    "scaled to what the velocity bounds reach, then met as nearly as they "
    "allow together (least squares; backing out)"
)


def _nearest_to_demands(
    problem: QPProblem,
    rows: IntArray,
    given: tuple[FloatArray, FloatArray],
    reach: tuple[FloatArray, FloatArray],
    solver: QPSolver,
) -> FloatArray | None:
    """The step nearest to meeting the demands of ``rows`` together, or None.

    Inequality demands that cannot all be met (the arm inside the safety
    distance of obstacles on two sides) are scaled by one factor, so that
    each asks at most half of what the velocity bounds let its row reach
    (``reach``: the row's largest and smallest value within them), then
    widened by their least violation (sum of squares) that the other rows
    allow; the step is the QP's optimum within them. One factor keeps what
    the rows ask in proportion: the arm backs away from the side that asks
    most (the nearer obstacle) instead of holding still, which scaling every
    demand to "no further" did; capped one by one, rows that asked for
    different motions asked alike. Step validation still refuses a step
    that ends deeper in an obstacle where it is. Measured on the generated
    scene moving_11 (cameras, wall clock): two boxes' moving cells, measured
    nearer in every direction, held the arm at k = 0 while the faster box
    reached it. ``given``: the rows' bounds as assembled. Leaves the widened
    bounds in ``problem``.
    """
    lo, hi = given
    up, down = lo > EASE_TOL, hi < -EASE_TOL
    room = np.concatenate(
        [0.5 * reach[0][up] / lo[up], 0.5 * reach[1][down] / hi[down]]
    )
    # A row its bounds let go nowhere (no room) is left to the least violation.
    room = room[room > 0.0]
    factor = float(min(1.0, np.min(room))) if room.size else 1.0
    lower, upper = lo.copy(), hi.copy()
    lower[up] *= factor
    upper[down] *= factor
    problem.lower[rows], problem.upper[rows] = lower, upper
    found = _least_violation(problem, rows, np.zeros(len(problem.lower), bool), solver)
    if found is None:
        return None
    violation, nearest = found
    widen = violation + GIVE_WAY_TOL
    problem.lower[rows] -= widen
    problem.upper[rows] += widen
    try:
        return solver.solve(problem)
    except SolveError:
        return nearest  # the least violation's own step: within every bound


def _give_way(
    problem: QPProblem, error: SolveError, solver: QPSolver, levels: IntArray
) -> tuple[FloatArray, Easing]:
    """The step with the rows that cannot hold given way in order; else re-raise.

    Leaves the widened bounds of the answer in ``problem``.
    """
    nv = problem.nv
    lower, upper, equality = problem.lower, problem.upper, problem.equality
    hard = ~problem.A[:, nv:].any(axis=1)
    level = np.where(hard, levels[problem.row_entry], LIMITS)
    level[hard & equality & (level > LIMITS)] = EQUALITIES
    given = (lower.copy(), upper.copy(), equality.copy())
    gave: dict[int, float] = {}
    fallback: FloatArray | None = None
    for stage in range(POSITIONS, EQUALITIES + 1):
        rows = np.flatnonzero(level == stage)
        if rows.size == 0:
            continue
        later = level > stage
        found = _least_violation(problem, rows, later, solver)
        if found is None:
            lower[:], upper[:], equality[:] = given
            raise error
        violation, fallback = found
        # Every row the least violation leaves violated is widened by as much
        # (and the solver's tolerance); past GIVE_WAY_TOL it "gave way".
        giving = violation > 0.0
        if giving.any():
            widen = violation[giving] + GIVE_WAY_TOL
            lower[rows[giving]] -= widen
            upper[rows[giving]] += widen
            equality[rows[giving]] = False
            for r, amount in zip(
                rows[giving].tolist(), violation[giving].tolist(), strict=True
            ):
                if amount > GIVE_WAY_TOL:
                    entry = int(problem.row_entry[r])
                    gave[entry] = max(gave.get(entry, 0.0), amount)
    try:
        x = solver.solve(problem)
    except SolveError:
        if fallback is None:
            lower[:], upper[:], equality[:] = given
            raise error from None
        x = fallback  # the last level's least violation: within every bound
    names = ", ".join(problem.entry_names[i] for i in sorted(gave)) or "no row"
    return x, Easing(
        f"{names} gave way, in order (position limits, then other constraints, "
        "then tasks and equalities; never the velocity and acceleration limits)",
        None,
    )


def _least_violation(
    problem: QPProblem, rows: IntArray, free: np.ndarray, solver: QPSolver
) -> tuple[FloatArray, FloatArray] | None:
    """The least violations of ``rows`` (sum of squares) the other rows allow.

    Rows marked ``free`` are left out; the others keep their bounds. Returns
    the violations and the QP's variables there; None when even with ``rows``
    left out the QP is infeasible.
    """
    A, nv = problem.A, problem.nv
    n, k = A.shape[1], rows.size
    kept = np.flatnonzero(~free)
    kept = kept[~np.isin(kept, rows)]
    H = np.zeros((n + k, n + k))
    H[np.diag_indices(n)] = GIVE_WAY_REGULARIZATION
    H[n:, n:] = np.eye(k)
    eye = np.eye(k)
    stacked = np.block(
        [
            [A[kept], np.zeros((kept.size, k))],
            [A[rows], eye],  # A x + s >= lower
            [A[rows], -eye],  # A x - s <= upper
            [np.zeros((k, n)), eye],  # s >= 0
        ]
    )
    inf = np.full(k, np.inf)
    relaxed = QPProblem(
        H=H,
        g=np.zeros(n + k),
        A=stacked,
        lower=np.concatenate(
            [problem.lower[kept], problem.lower[rows], -inf, np.zeros(k)]
        ),
        upper=np.concatenate([problem.upper[kept], inf, problem.upper[rows], inf]),
        equality=np.concatenate([problem.equality[kept], np.zeros(3 * k, dtype=bool)]),
        row_entry=np.concatenate(
            [problem.row_entry[kept]] + [problem.row_entry[rows]] * 3
        ),
        entry_names=problem.entry_names,
        nv=nv,
    )
    try:
        x = solver.solve(relaxed)
    except SolveError:
        return None
    return np.maximum(np.asarray(x[n:]), 0.0), np.asarray(x[:n])


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
