# SPDX-License-Identifier: Apache-2.0
"""The engine: one QP per step from a list of task and constraint entries."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence
from typing import NamedTuple

import numba
import numpy as np

from cbp.engine.ahead import CoastingDrift
from cbp.engine.guard import StepGuard
from cbp.engine.recovery import Easing, ease, give_way_levels
from cbp.errors import ConfigError, InvalidStateError, SolveError, suggestion
from cbp.plugin import AnyPlugin, Plugin
from cbp.qp import Entry, QPAssembler, QPProblem
from cbp.robot import FloatArray, RobotModel
from cbp.solvers import QPSolver, make_solver
from cbp.state import RobotState

__all__ = ["Engine", "StepResult"]


class StepResult(NamedTuple):
    """What one engine step did: the step, and how it came to be.

    Attributes:
        dq: the joint displacement (nv), as the step guard let it through.
        problem: the QP that was solved (its bounds as eased). The engine's
            own buffers: valid until its next step.
        eased: how the QP was eased to be solvable (None: solved as
            assembled).
        slowed: how many times too fast the answer was before the guard
            slowed it to the velocity limits (1.0: it was not).
    """

    dq: FloatArray
    problem: QPProblem
    eased: Easing | None
    slowed: float


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
        guard: the step guard every answer passes (:mod:`cbp.engine.guard`).
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
        self._nq, self._nv = robot.nq, robot.nv
        self.entries = list(entries)
        self.solver = make_solver(solver) if isinstance(solver, str) else solver
        self.assembler = QPAssembler(self.entries, robot.nv, regularization)
        self.state = RobotState(robot)
        self.guard = StepGuard(robot, limit_tolerance, max_step, self._joint_of)
        self._by_name = {e.name: e for e in self.entries}
        # Plugins that latch something at the start of a step (the others keep
        # the base class's empty prepare and are not called for it).
        plugins = [e.plugin for e in self.entries]
        self._latching = [p for p in plugins if type(p).prepare is not Plugin.prepare]
        # Per entry: whether its rows may be eased when the QP is infeasible.
        self._easable = np.array([p.easable for p in plugins], dtype=bool)
        # Per entry: when its rows give way if not all can hold.
        self._levels = give_way_levels(plugins)
        # The second-order drift of the rows over a step of a moving robot.
        self._drift = CoastingDrift(robot, self.entries)
        _all_finite(np.zeros(robot.nq))  # compiled now, not in the first step

    def plugin(self, name: str) -> AnyPlugin:
        """Return the plugin of the entry called ``name``."""
        try:
            return self._by_name[name].plugin
        except KeyError:
            raise ConfigError(
                f"no entry named '{name}'{suggestion(name, self._by_name)} "
                f"Entries: {', '.join(self._by_name)}."
            ) from None

    def step(self, q: FloatArray, dt: float, v: FloatArray | None = None) -> StepResult:
        """One step of duration ``dt`` from ``q``: the displacement, and how.

        ``v`` is the joint velocity the robot has at ``q`` (nv): an executor
        that commands velocities gives its last command, and plugins read it as
        ``state.v`` (``joint_acceleration`` bounds the step's change of
        velocity with it). None: at rest, and the guard checks no acceleration.
        Given, the bounds of the hard constraint rows are moved by the
        second-order drift of coasting at ``v`` for ``dt``
        (:class:`cbp.engine.ahead.CoastingDrift`).

        When the QP is infeasible because hard rows ask for more motion than the
        others allow (the arm inside its safety distance or in penetration, a
        joint past its limit), those rows are eased and the step solved again
        (:func:`cbp.engine.recovery.ease`); the result's ``eased`` says how.

        Every answer passes the step guard (:class:`cbp.engine.guard.StepGuard`)
        before it is returned: what reaches a robot is finite, within the
        velocity limits for ``dt`` (slowed down uniformly to them, the result's
        ``slowed``, when a configuration has no velocity constraint), within
        the acceleration limits from ``v`` when it is given, and within the
        joint limits.

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
        if v is not None:
            self._drift.apply(problem, self.assembler.values, state, v, float(dt))
        eased: Easing | None = None
        # An infeasible step is eased (pressed by obstacles, it is the usual
        # answer): its conflicts are named only when nothing eases it. Naming
        # them first took a fifth of the step's time where obstacles pressed.
        with self.solver.trials():
            try:
                x = self.solver.solve(problem)
            except SolveError as exc:
                try:
                    x, eased = ease(
                        problem,
                        exc,
                        float(dt),
                        self.solver,
                        self._easable,
                        state.v,
                        self._levels,
                    )
                except SolveError as failed:
                    raise self.solver.explained(failed) from None
        if v is not None and self._drift.refine(problem, state, x[: self._nv]):
            # The rows that hold the step, with the drift of the step found;
            # if that cannot be solved, the first answer (third order off),
            # and no diagnosis is spent on a failure that is not raised.
            with contextlib.suppress(SolveError), self.solver.trials():
                x = self.solver.solve(problem)
        dq, slowed = self.guard.check(q, x[: self._nv], dt, v)
        return StepResult(dq, problem, eased, slowed)

    def _checked(self, q: FloatArray, dt: float) -> FloatArray:
        """``q`` as a float array, after checking it and ``dt``."""
        if not (isinstance(dt, (int, float, np.floating)) and math.isfinite(dt)):
            raise InvalidStateError(f"dt must be a finite number, got {dt!r}")
        if dt <= 0.0:
            raise InvalidStateError(f"dt must be > 0, got {dt}")
        if (
            type(q) is np.ndarray
            and q.dtype is _FLOAT
            and q.shape == (self._nq,)
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


#: The dtype of the configurations checked in one compiled pass (numpy's
#: built-in dtypes are singletons; any other goes the long way).
_FLOAT = np.dtype(np.float64)


@numba.njit(cache=True, nogil=True)
def _all_finite(x: FloatArray) -> bool:
    """Whether every entry of ``x`` is finite."""
    return bool(np.isfinite(x).all())
