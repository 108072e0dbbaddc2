# SPDX-License-Identifier: Apache-2.0
"""The engine: one QP per step from a list of task and constraint entries."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numba
import numpy as np

from cbp.errors import (
    ConfigError,
    InvalidStateError,
    SolveError,
    UnsafeStepError,
    suggestion,
)
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
        limit_tolerance: how far beyond a joint's position limit the step guard
            lets a step end [rad or m] (solvers meet bounds to about 1e-9).
        max_step: the largest step of a joint that has no velocity limit, per
            second of the step's duration [rad/s or m/s].

    Attributes:
        state: the state of the last step (kinematics at its start).
        problem: the QP of the last step, for inspection.
        recovery: how the last step's QP was eased to be solvable (None: it
            was solved as assembled); see :meth:`step`.
        recovery_changed: whether :attr:`recovery` differs from that of the
            solved step before (so a run reports each change once).
        recovery_scale: when the last step's demands were scaled down, the
            factor they were scaled by (0: held); else None.
    """

    def __init__(
        self,
        robot: RobotModel,
        entries: Sequence[Entry],
        solver: str | QPSolver = "daqp",
        regularization: float = 1e-9,
        limit_tolerance: float = 1e-4,
        max_step: float = 10.0,
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
        self.limit_tolerance = float(limit_tolerance)
        velocity = np.asarray(robot.velocity_limits, dtype=float)
        #: The guard's speed bound per joint (nv) [per s]: the velocity limit
        #: with 1 % for the solver's tolerance; ``max_step`` where there is none.
        self.speed_bound = np.where(
            np.isfinite(velocity), 1.01 * velocity + 1e-9, float(max_step)
        )
        #: The guard's acceleration bound per joint (nv) [per s^2], with 1 % for
        #: the solver's tolerance; checked when a step is given the velocity.
        self.acceleration_bound = (
            1.01 * np.asarray(robot.acceleration_limits, dtype=float) + 1e-9
        )
        self._has_limits = bool(
            np.isfinite(robot.lower_limits).any()
            or np.isfinite(robot.upper_limits).any()
        )
        self.problem: QPProblem | None = None
        #: How many times too fast the last step was before the guard slowed it
        #: to the velocity limits (1.0: it was not).
        self.slowed = 1.0
        self.recovery: str | None = None
        self.recovery_scale: float | None = None
        self.recovery_changed = False
        self._solved_recovery: str | None = None
        self._by_name = {e.name: e for e in self.entries}
        # Plugins that latch something at the start of a step (the others keep
        # the base class's empty prepare and are not called for it).
        plugins = [e.plugin for e in self.entries]
        self._latching = [p for p in plugins if type(p).prepare is not Plugin.prepare]
        # Per entry: whether its rows may be eased when the QP is infeasible.
        self._easable = np.array([p.easable for p in plugins], dtype=bool)

    def plugin(self, name: str) -> AnyPlugin:
        """Return the plugin of the entry called ``name``."""
        try:
            return self._by_name[name].plugin
        except KeyError:
            raise ConfigError(
                f"no entry named '{name}'{suggestion(name, self._by_name)} "
                f"Entries: {', '.join(self._by_name)}."
            ) from None

    def step(self, q: FloatArray, dt: float, v: FloatArray | None = None) -> FloatArray:
        """Return the displacement dq (nv) of one step of duration ``dt`` from ``q``.

        ``v`` is the joint velocity the robot has at ``q`` (nv): an executor
        that commands velocities gives its last command, and plugins read it as
        ``state.v`` (``joint_acceleration`` bounds the step's change of
        velocity with it). None: at rest, and the guard checks no acceleration.

        When the QP is infeasible because hard rows ask for more motion than the
        others allow (the arm inside its safety distance or in penetration, a
        joint past its limit), those rows are eased and the step solved again
        (:meth:`_recover`); :attr:`recovery` then says how.

        Every answer passes the step guard (:meth:`guard_step`) before it is
        returned: what reaches a robot is finite, within the velocity limits for
        ``dt`` (slowed down uniformly to them, :attr:`slowed`, when a
        configuration has no velocity constraint), within the acceleration
        limits from ``v`` when it is given, and within the joint limits.

        Raises:
            SolveError: the QP is infeasible or the backend failed; nothing moved.
            UnsafeStepError: (a SolveError) the answer failed the step guard.
            PluginOutputError: a plugin returned a malformed or non-finite output.
            InvalidStateError: ``q`` is not a finite configuration of the robot,
                ``v`` not a finite velocity, or ``dt`` not a finite positive
                duration.
        """
        q = self._checked(q, dt)
        if v is not None:
            v = self._checked_velocity(v)
        state = self.state
        state.update(q)
        state.set_velocity(v)
        for plugin in self._latching:
            plugin.prepare(state, dt)
        problem = self.assembler.assemble(state)
        self.problem = problem
        self.recovery = None
        self.recovery_scale = None
        try:
            x = self.solver.solve(problem)
        except SolveError as exc:
            x = self._recover(problem, exc, float(dt))
        dq = self.guard_step(q, x[: self.robot.nv], dt, v)
        self.recovery_changed = self.recovery != self._solved_recovery
        self._solved_recovery = self.recovery
        return dq

    def guard_step(
        self, q: FloatArray, dq: FloatArray, dt: float, v: FloatArray | None = None
    ) -> FloatArray:
        """The step guard: ``dq`` if it is safe, slowed if only too fast.

        Safe: finite; no joint faster than its velocity limit over ``dt`` (with
        1 % for solver tolerances; :attr:`speed_bound`); when the velocity ``v``
        at ``q`` is given, no joint's velocity changing from it faster than its
        acceleration limit (with 1 %; :attr:`acceleration_bound`); ``q`` ⊕
        ``dq`` within the position limits by :attr:`limit_tolerance`, or, for a
        joint that starts beyond its limit, no further beyond than it starts. A
        step up to :data:`GARBAGE_RATIO` times too fast is scaled down as a
        whole to the velocity limits (same direction: it still meets every row
        it met whose bound allows standing still) and :attr:`slowed` says by
        how much; a faster one is garbage and rejected. A step that accelerates
        too hard cannot be scaled into shape and is rejected.

        Raises:
            UnsafeStepError: the step is not finite, is garbage, accelerates a
                joint past its limit, or ends beyond a joint limit; the message
                names the joint and the amount.
        """
        robot = self.robot
        self.slowed = 1.0
        dq = np.ascontiguousarray(dq, dtype=float)
        if dq.shape != (robot.nv,):
            raise UnsafeStepError(f"step rejected: {dq.shape} values, not {robot.nv}")
        i, worst = _speed_ratio(dq, self.speed_bound, float(dt))
        if i < 0:
            raise UnsafeStepError(
                f"step rejected: the solver's answer is not finite ({dq})"
            )
        if worst > GARBAGE_RATIO:
            raise UnsafeStepError(
                f"step rejected: {self._velocity_name(i)} would move "
                f"{abs(dq[i]):.4g} in {dt:.4g} s, {worst:.3g} times its limit "
                f"({self.speed_bound[i]:.4g}/s)"
            )
        if worst > 1.0:
            dq = dq / worst
            self.slowed = worst
        if v is not None:
            j, harder = _acceleration_ratio(dq, v, self.acceleration_bound, float(dt))
            if harder > 1.0:
                raise UnsafeStepError(
                    f"step rejected: {self._velocity_name(j)} would change its "
                    f"velocity from {v[j]:.4g} to {dq[j] / dt:.4g} in {dt:.4g} s, "
                    f"{harder:.3g} times its acceleration limit "
                    f"({self.acceleration_bound[j]:.4g}/s^2)"
                )
        if not self._has_limits:
            return dq
        q_next = q + dq if robot.is_euclidean else robot.integrate(q, dq)
        lower, upper = robot.lower_limits, robot.upper_limits
        k, beyond = _past_limits(q, q_next, lower, upper, self.limit_tolerance)
        if k >= 0:
            raise UnsafeStepError(
                f"step rejected: coordinate {self._position_name(k)} would "
                f"end {beyond:.4g} beyond its limits [{lower[k]:.4g}, "
                f"{upper[k]:.4g}]"
            )
        return dq

    def _checked(self, q: FloatArray, dt: float) -> FloatArray:
        """``q`` as a float array, after checking it and ``dt``."""
        if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt)):
            raise InvalidStateError(f"dt must be a finite number, got {dt!r}")
        if dt <= 0.0:
            raise InvalidStateError(f"dt must be > 0, got {dt}")
        nq = self.robot.nq
        if (
            type(q) is np.ndarray
            and q.dtype == np.float64
            and q.shape == (nq,)
            and _all_finite(q)
        ):
            return q  # the common case, checked in one compiled pass
        try:
            return self.robot.check_configuration(q)
        except ConfigError as exc:
            raise InvalidStateError(str(exc)) from None

    def _checked_velocity(self, v: FloatArray) -> FloatArray:
        """``v`` as a float array of nv finite values, or InvalidStateError."""
        nv = self.robot.nv
        try:
            v = np.asarray(v, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InvalidStateError(f"v is not a velocity: {exc}") from None
        if v.shape != (nv,):
            raise InvalidStateError(f"v must have {nv} values, got shape {v.shape}")
        if not _all_finite(np.ascontiguousarray(v)):
            raise InvalidStateError(f"v must be finite, got {v}")
        return v

    def _velocity_name(self, i: int) -> str:
        """The joint that tangent coordinate ``i`` belongs to."""
        return f"joint {self._joint_of(i, 'v')}"

    def _position_name(self, i: int) -> str:
        """The joint that configuration coordinate ``i`` belongs to."""
        return self._joint_of(i, "q")

    def _joint_of(self, i: int, space: str) -> str:
        """The quoted name of the joint whose ``space`` (q or v) holds index i."""
        model = self.robot.model
        for j in range(1, model.njoints):
            joint = model.joints[j]
            first, size = (
                (joint.idx_q, joint.nq) if space == "q" else (joint.idx_v, joint.nv)
            )
            if first <= i < first + size:
                return f"'{model.names[j]}'"
        return str(i)

    def _recover(self, problem: QPProblem, error: SolveError, dt: float) -> FloatArray:
        """Solve again with the hard rows that ask for motion eased; else re-raise.

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
        its acceleration limits always allow. Rows of plugins that are physical limits
        (``easable = False``: ``joint_acceleration``) are never eased.
        :attr:`recovery` says what was done.
        """
        lower, upper = problem.lower, problem.upper
        nv = self.robot.nv
        # Hard (no slack variable) rows of easable entries.
        hard = ~problem.A[:, nv:].any(axis=1) & self._easable[problem.row_entry]
        asks_up, asks_down = lower > _EASE_TOL, upper < -_EASE_TOL
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
            lower[capped] = np.minimum(
                lower[capped], 0.5 * np.maximum(reach_hi[capped], 0)
            )
            upper[capped] = np.maximum(
                upper[capped], 0.5 * np.minimum(reach_lo[capped], 0)
            )
            try:
                x = self.solver.solve(problem)
            except SolveError:
                pass
            else:
                if not equality.any():
                    self.recovery = (
                        what + "eased to half of what the velocity bounds reach "
                        "(backing out)"
                    )
                    return x
            lower[rows], upper[rows] = given  # infeasible, or equalities to scale

        # An equality is scaled from the value its row has if the robot keeps
        # its velocity (the state's v; zero at rest), which the acceleration
        # rows always allow; an inequality from zero, "no further".
        equal = problem.equality[rows]
        anchor = np.zeros(rows.size)
        anchor[equal] = problem.A[rows[equal], :nv] @ (self.state.v * dt)

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
                return self.solver.solve(problem)
            except SolveError:
                return None

        best = scaled(0.0)
        if best is None:
            lower[rows], upper[rows] = given
            raise error
        low, high = 0.0, 1.0
        for _ in range(_SCALE_BISECTIONS):
            middle = 0.5 * (low + high)
            found = scaled(middle)
            if found is None:
                high = middle
            else:
                low, best = middle, found
        scale(low)  # leave the bounds of the answer in self.problem
        self.recovery_scale = low
        if low == 0.0:
            self.recovery = what + "held (k = 0: no further, no change)"
        else:
            self.recovery = what + "scaled down to what the limits allow"
        return best


@numba.njit(cache=True, nogil=True)
def _all_finite(x: FloatArray) -> bool:
    """Whether every entry of ``x`` is finite."""
    return bool(np.isfinite(x).all())


@numba.njit(cache=True, nogil=True)
def _speed_ratio(dq: FloatArray, bound: FloatArray, dt: float) -> tuple[int, float]:
    """(the fastest coordinate, its |dq| / (bound dt)); (-1, nan) if not finite."""
    worst, at = 0.0, 0
    for i in range(dq.size):
        if not math.isfinite(dq[i]):
            return -1, math.nan
        ratio = abs(dq[i]) / (bound[i] * dt)
        if ratio > worst:
            worst, at = ratio, i
    return at, worst


@numba.njit(cache=True, nogil=True)
def _acceleration_ratio(
    dq: FloatArray, v: FloatArray, bound: FloatArray, dt: float
) -> tuple[int, float]:
    """(the hardest-accelerating coordinate, its |dq/dt - v| / (bound dt))."""
    worst, at = 0.0, 0
    for i in range(dq.size):
        ratio = abs(dq[i] / dt - v[i]) / (bound[i] * dt)
        if ratio > worst:
            worst, at = ratio, i
    return at, worst


@numba.njit(cache=True, nogil=True)
def _past_limits(
    q: FloatArray, q_next: FloatArray, lower: FloatArray, upper: FloatArray, tol: float
) -> tuple[int, float]:
    """The coordinate that ends furthest past its limits, and how far.

    Only by more than ``tol`` and further than it starts; (-1, 0) if none.
    """
    worst, at = 0.0, -1
    for i in range(q.size):
        beyond = max(lower[i] - q_next[i], q_next[i] - upper[i])
        started = max(lower[i] - q[i], q[i] - upper[i])
        if beyond > max(tol, started + 1e-12, worst):
            worst, at = beyond, i
    return at, worst


#: A step more than this many times faster than a joint's velocity limit allows
#: is garbage (a solver fault), not a step to slow down: the guard rejects it.
GARBAGE_RATIO = 10.0

#: A hard row's bound within this of zero does not count as asking for motion.
_EASE_TOL = 1e-12

#: Bisection steps for the largest feasible scale of the demands (1/64).
_SCALE_BISECTIONS = 6


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
