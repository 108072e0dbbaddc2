# SPDX-License-Identifier: Apache-2.0
"""Constraint ``joint_acceleration``: bound each step's change of joint velocity."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar, Literal

import numba
import numpy as np

from cbp.errors import ConfigError
from cbp.joint_space import StepDisplacement, check_scaled_limits, limits_by_joint
from cbp.plugin import Constraint, FloatArray, PluginParams, RobotLimit
from cbp.robot import IntArray, RobotModel, compact_rows
from cbp.state import RobotState


@dataclass(frozen=True, kw_only=True)
class JointAccelerationParams(PluginParams):
    """Parameters of :class:`JointAccelerationConstraint`."""

    scale: float = 1.0
    """Fraction of the robot's acceleration limits to allow, in (0, 1]."""
    limits: dict[str, float] = field(default_factory=dict)
    """Acceleration limits by joint name that replace the robot's
    [rad/s^2 or m/s^2]."""
    margin: float = 0.0
    """Distance from each position limit at which a joint must be able to
    stop [rad or m]: the ``joint_limits`` constraint's margin."""
    braking: Literal["slowest", "own"] = "slowest"
    """How hard a joint may have to brake before its position limit:
    ``slowest``, the smallest (scaled) acceleration limit of the robot's
    joints, so that the joints that take over its share of a task (a mobile
    base, slower than the arm) can keep up while it stops; ``own``, its own
    limit (it runs closer to the limit before it brakes)."""

    def __post_init__(self) -> None:
        """Scale in (0, 1], limits positive, margin not negative."""
        if not self.margin >= 0:
            raise ConfigError(f"must be >= 0, got {self.margin}", "margin")
        check_scaled_limits(self.scale, self.limits)


class JointAccelerationConstraint(
    StepDisplacement[JointAccelerationParams], Constraint[JointAccelerationParams]
):
    r"""The step's velocity within reach of the velocity the robot has.

    .. math:: (v_0 - s\,a_{max}\,\Delta t)\,\Delta t \le q \ominus q_0
              \le (v_0 + s\,a_{max}\,\Delta t)\,\Delta t

    and, for a joint with a position range, no faster toward a limit than it
    can brake before it (the limit less ``margin``; :math:`d` the distance
    left, :math:`a = s\,a_{max}`):
    :math:`|\Delta q| / \Delta t \le -\tfrac32 a \Delta t +
    \sqrt{(\tfrac32 a \Delta t)^2 + 2 a d}`, the speed from which the joint
    stops within :math:`d` one tick later. Without it, a position limit met at
    speed would need more deceleration than the joint has, and the QP would be
    infeasible. A joint already too fast for that brakes as hard as it can.
    With ``braking: slowest`` (the default) :math:`a` is the smallest limit of
    any joint: an arm joint that stopped at 3 rad/s^2 would hand its share of
    the orbit's view to a base that takes it up at 1 rad/s^2, and the view
    would give way meanwhile.

    where :math:`q_0` is the configuration at the start of the step and
    :math:`v_0` its velocity (``state.v``: the executor's last command), both
    latched by :meth:`prepare` with the step duration :math:`\Delta t`. For an
    executor that commands :math:`u = \Delta q / \Delta t` each tick (the
    velocity executor) the rows are :math:`|u - u_{prev}| \le s\,a_{max}\,\Delta t`:
    no command asks a joint for more than it can accelerate, so the QP's other
    rows hold for the velocity the robot really reaches. Dimension: the tangent
    coordinates [rad or m]. The Jacobian selects them. No singularity.

    When the robot moves faster than the other rows allow (a constraint that
    suddenly asks it to stop), the rows exclude standing still and the QP can
    be infeasible; the engine then eases them (see
    :meth:`cbp.engine.Engine.step`) and its step guard, which checks the same
    limits, has the executor brake within them.
    """

    type_name: ClassVar[str] = "joint_acceleration"
    unit: ClassVar[str] = "rad"
    robot_limit: ClassVar[RobotLimit | None] = "acceleration"
    easable: ClassVar[bool] = False  # the robot cannot accelerate faster
    #: Why the loader added this entry to a scenario that had none (None: the
    #: scenario lists it).
    added_because: str | None = None

    def __init__(
        self, params: JointAccelerationParams, robot: RobotModel, name: str = ""
    ) -> None:
        """Gather the limits and keep the coordinates that have one."""
        super().__init__(params, robot, name)
        finite, acceleration = limits_by_joint(
            robot, robot.acceleration_limits, params.limits
        )
        self.rows = compact_rows(finite)
        self._finite = finite
        self._acceleration = params.scale * acceleration
        # The rows (positions in ``finite``) of joints with a position range,
        # their configuration coordinates and their limits less the margin.
        row_of = {int(v): i for i, v in enumerate(finite)}
        ranged = [
            (row_of[int(v)], int(qi))
            for qi, v in zip(robot.bounded_q, robot.bounded_v, strict=True)
            if int(v) in row_of
        ]
        self._ranged = np.array([r for r, _ in ranged], dtype=int)
        self._ranged_q = np.array([qi for _, qi in ranged], dtype=int)
        braking = self._acceleration[self._ranged]
        if params.braking == "slowest" and braking.size:
            braking = np.full(braking.size, float(np.min(self._acceleration)))
        self._braking = braking
        self._low_limit = robot.lower_limits[self._ranged_q] + params.margin
        self._high_limit = robot.upper_limits[self._ranged_q] - params.margin
        self._lower = np.zeros(finite.size)
        self._upper = np.zeros(finite.size)
        # Compile the bounds' pass (or load it from numba's cache) now, on
        # arrays of the kinds a step passes (a state's are read-only).
        rest, neutral = np.zeros(robot.nv), robot.neutral()
        rest.flags.writeable = neutral.flags.writeable = False
        self._bounds_at(rest, neutral, 0.01)
        self._lower[:] = self._upper[:] = 0.0  # no bounds until the first step

    def _bounds_at(self, v: FloatArray, q: FloatArray, dt: float) -> None:
        """The rows' bounds at velocity ``v`` and configuration ``q``, in place."""
        _step_bounds(
            v,
            q,
            float(dt),
            self._finite,
            self._acceleration,
            self._ranged,
            self._ranged_q,
            self._braking,
            self._low_limit,
            self._high_limit,
            self._lower,
            self._upper,
        )

    def prepare(self, state: RobotState, dt: float) -> None:
        """Latch the start configuration, its velocity and the step duration."""
        super().prepare(state, dt)
        self._bounds_at(state.v, state.q, dt)

    def compute_bounds(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """(v_0 ∓ scaled acceleration limit x dt) x dt."""
        return self._lower, self._upper

    def __repr__(self) -> str:
        """Type, name, scale and limits."""
        return (
            f"JointAccelerationConstraint(name={self.name!r}, "
            f"scale={self.params.scale}, limits={self.params.limits!r}, "
            f"margin={self.params.margin}, braking={self.params.braking!r})"
        )


@numba.njit(cache=True, nogil=True)
def _step_bounds(
    v: FloatArray,
    q: FloatArray,
    dt: float,
    finite: IntArray,
    acceleration: FloatArray,
    ranged: IntArray,
    ranged_q: IntArray,
    braking: FloatArray,
    low_limit: FloatArray,
    high_limit: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
) -> None:
    """The rows' bounds of one step, into ``lower`` and ``upper`` (one pass).

    The velocities within reach of ``v`` over ``dt``; for a joint with a
    position range (``ranged``: its row; ``ranged_q``: its coordinate) no
    faster toward a limit than it can brake at ``braking`` before it; a joint
    too fast to stop in time brakes as hard as it can. Times ``dt``.
    """
    for i in range(finite.size):
        reach = acceleration[i] * dt
        lower[i] = v[finite[i]] - reach
        upper[i] = v[finite[i]] + reach
    for j in range(ranged.size):
        r = ranged[j]
        position = q[ranged_q[j]]
        up = _braking_speed(braking[j], dt, high_limit[j] - position)
        down = _braking_speed(braking[j], dt, position - low_limit[j])
        upper[r] = max(min(upper[r], up), lower[r])
        lower[r] = min(max(lower[r], -down), upper[r])
    for i in range(finite.size):
        lower[i] *= dt
        upper[i] *= dt


@numba.njit(cache=True, nogil=True)
def _braking_speed(a: float, dt: float, distance: float) -> float:
    """The speed from which a joint moving one tick more stops within ``distance``.

    Solves v dt + v dt / 2 + v^2 / (2 a) = d for v >= 0 (one tick at v, then
    braking at ``a`` in ticks of ``dt``, whose distance is at most
    v^2 / (2 a) + v dt / 2); 0 when the distance is not positive.
    """
    b = 1.5 * a * dt
    return -b + math.sqrt(b * b + 2.0 * a * max(distance, 0.0))
