# SPDX-License-Identifier: Apache-2.0
"""The step guard: what reaches a robot is finite and within its limits.

Every answer of the QP passes :meth:`StepGuard.check` before the engine
returns it (:meth:`cbp.engine.Engine.step`), whatever the solver, the plugins
or the easing did.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba
import numpy as np

from cbp.errors import UnsafeStepError
from cbp.robot import FloatArray, RobotModel

__all__ = ["GARBAGE_RATIO", "StepGuard"]

#: A step more than this many times faster than a joint's velocity limit allows
#: is garbage (a solver fault), not a step to slow down: the guard rejects it.
GARBAGE_RATIO = 10.0


class StepGuard:
    """Checks one step against the robot's velocity, acceleration and joint limits.

    Args:
        robot: the robot model.
        limit_tolerance: how far beyond a joint's position limit a step may end
            [rad or m] (solvers meet bounds to about 1e-9).
        max_step: the largest step of a joint that has no velocity limit, per
            second of the step's duration [rad/s or m/s].
        joint_name: names the joint of a tangent (``"v"``) or configuration
            (``"q"``) coordinate, for messages.

    Attributes:
        speed_bound: per joint (nv) [per s]: the velocity limit with 1 % for
            the solver's tolerance; ``max_step`` where there is none.
        acceleration_bound: per joint (nv) [per s^2], with 1 % for the
            solver's tolerance; checked when a step is given the velocity.
        limit_tolerance: as given.
    """

    def __init__(
        self,
        robot: RobotModel,
        limit_tolerance: float,
        max_step: float,
        joint_name: Callable[[int, str], str],
    ) -> None:
        """Compute the bounds once."""
        self.robot = robot
        self.limit_tolerance = float(limit_tolerance)
        velocity = np.asarray(robot.velocity_limits, dtype=float)
        self.speed_bound = np.where(
            np.isfinite(velocity), 1.01 * velocity + 1e-9, float(max_step)
        )
        self.acceleration_bound = (
            1.01 * np.asarray(robot.acceleration_limits, dtype=float) + 1e-9
        )
        self._has_limits = bool(
            np.isfinite(robot.lower_limits).any()
            or np.isfinite(robot.upper_limits).any()
        )
        self._joint_name = joint_name
        self._shape = (robot.nv,)
        self._euclidean = bool(robot.is_euclidean)
        # The four bounds of a Euclidean robot in one array: the compiled check
        # takes it as one argument (each array costs numba's dispatch ~50 ns).
        self._bounds = (
            np.stack(
                [
                    self.speed_bound,
                    self.acceleration_bound,
                    robot.lower_limits,
                    robot.upper_limits,
                ]
            )
            if self._euclidean
            else np.zeros((4, 0))
        )
        self._compile(robot)

    def _compile(self, robot: RobotModel) -> None:
        """Compile the checks (or load them from numba's cache) on a zero step.

        Here, when the engine is made, rather than in its first control step;
        on arrays of the kinds a step passes (writeable q, step and velocity;
        the robot's read-only limits).
        """
        q, dq = np.zeros(robot.nq), np.zeros(robot.nv)
        if self._euclidean:
            _euclidean_check(q, dq, self._bounds, 0.01, dq, True, 1e-4, True)
        _speed_ratio(dq, self.speed_bound, 0.01)
        _acceleration_ratio(dq, dq, self.acceleration_bound, 0.01)
        _past_limits(q, q, robot.lower_limits, robot.upper_limits, 1e-4)

    def check(
        self, q: FloatArray, dq: FloatArray, dt: float, v: FloatArray | None = None
    ) -> tuple[FloatArray, float]:
        """``dq`` if it is safe, slowed if only too fast; and by how much.

        Safe: finite; no joint faster than its velocity limit over ``dt``
        (:attr:`speed_bound`); when the velocity ``v`` at ``q`` is given, no
        joint's velocity changing from it faster than its acceleration limit
        (:attr:`acceleration_bound`); ``q`` ⊕ ``dq`` within the position limits
        by :attr:`limit_tolerance`, or, for a joint that starts beyond its
        limit, no further beyond than it starts. A step up to
        :data:`GARBAGE_RATIO` times too fast is scaled down as a whole to the
        velocity limits (same direction: it still meets every row it met whose
        bound allows standing still); a faster one is garbage and rejected. A
        step that accelerates too hard cannot be scaled into shape and is
        rejected.

        Returns:
            The step, and how many times too fast it was before it was slowed
            (1.0: it was not).

        Raises:
            UnsafeStepError: the step is not finite, is garbage, accelerates a
                joint past its limit, or ends beyond a joint limit; the message
                names the joint and the amount.
        """
        robot = self.robot
        slowed = 1.0
        dq = np.ascontiguousarray(dq, dtype=float)
        if dq.shape != self._shape:
            raise UnsafeStepError(
                f"step rejected: {dq.shape} values, not {self._shape[0]}"
            )
        if self._euclidean and q.shape == dq.shape:
            # Every check in one compiled call; the messages below only when
            # one fails (the same checks, in the same order).
            code, slowed = _euclidean_check(
                q,
                dq,
                self._bounds,
                float(dt),
                _NO_VELOCITY if v is None else v,
                v is not None,
                self.limit_tolerance,
                self._has_limits,
            )
            if code == _SAFE:
                return (dq if slowed == 1.0 else dq / slowed), slowed
            slowed = 1.0
        i, worst = _speed_ratio(dq, self.speed_bound, float(dt))
        if i < 0:
            raise UnsafeStepError(
                f"step rejected: the solver's answer is not finite ({dq})"
            )
        if worst > GARBAGE_RATIO:
            raise UnsafeStepError(
                f"step rejected: joint {self._joint_name(i, 'v')} would move "
                f"{abs(dq[i]):.4g} in {dt:.4g} s, {worst:.3g} times its limit "
                f"({self.speed_bound[i]:.4g}/s)"
            )
        if worst > 1.0:
            dq = dq / worst
            slowed = worst
        if v is not None:
            j, harder = _acceleration_ratio(dq, v, self.acceleration_bound, float(dt))
            if harder > 1.0:
                raise UnsafeStepError(
                    f"step rejected: joint {self._joint_name(j, 'v')} would change "
                    f"its velocity from {v[j]:.4g} to {dq[j] / dt:.4g} in "
                    f"{dt:.4g} s, {harder:.3g} times its acceleration limit "
                    f"({self.acceleration_bound[j]:.4g}/s^2)"
                )
        if not self._has_limits:
            return dq, slowed
        q_next = q + dq if robot.is_euclidean else robot.integrate(q, dq)
        lower, upper = robot.lower_limits, robot.upper_limits
        k, beyond = _past_limits(q, q_next, lower, upper, self.limit_tolerance)
        if k >= 0:
            raise UnsafeStepError(
                f"step rejected: coordinate {self._joint_name(k, 'q')} would "
                f"end {beyond:.4g} beyond its limits [{lower[k]:.4g}, "
                f"{upper[k]:.4g}]"
            )
        return dq, slowed


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


#: What :func:`_euclidean_check` found: safe, or which check failed first.
_SAFE, _NOT_FINITE, _GARBAGE, _ACCELERATES, _PAST_LIMITS = range(5)

#: The velocity passed when there is none (not read).
_NO_VELOCITY = np.zeros(0)


@numba.njit(cache=True, nogil=True)
def _euclidean_check(
    q: FloatArray,
    dq: FloatArray,
    bounds: FloatArray,
    dt: float,
    v: FloatArray,
    has_v: bool,
    tol: float,
    has_limits: bool,
) -> tuple[int, float]:
    """Every check of :meth:`StepGuard.check` for a robot whose q ⊕ dq is q + dq.

    ``bounds`` is (4, nv): the speed and acceleration bounds, the lower and
    upper position limits. Returns (what it found, how many times too fast the
    step was: it is to be slowed by that when safe).
    """
    speed, acceleration, lower, upper = bounds[0], bounds[1], bounds[2], bounds[3]
    at, worst = _speed_ratio(dq, speed, dt)
    if at < 0:
        return _NOT_FINITE, 1.0
    if worst > GARBAGE_RATIO:
        return _GARBAGE, worst
    scale = 1.0 / worst if worst > 1.0 else 1.0
    slowed = worst if worst > 1.0 else 1.0
    if has_v:
        for i in range(dq.size):
            ratio = abs(dq[i] * scale / dt - v[i]) / (acceleration[i] * dt)
            if ratio > 1.0:
                return _ACCELERATES, slowed
    if has_limits:
        for i in range(q.size):
            end = q[i] + dq[i] * scale
            beyond = max(lower[i] - end, end - upper[i])
            started = max(lower[i] - q[i], q[i] - upper[i])
            if beyond > max(tol, started + 1e-12):
                return _PAST_LIMITS, slowed
    return _SAFE, slowed


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
