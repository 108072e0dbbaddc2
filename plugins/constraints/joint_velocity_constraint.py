# SPDX-License-Identifier: Apache-2.0
"""Constraint ``joint_velocity``: bound each step by the joints' velocity limits."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from cbp.joint_space import StepDisplacement, check_scaled_limits, limits_by_joint
from cbp.plugin import Constraint, FloatArray, PluginParams, RobotLimit
from cbp.robot import RobotModel, compact_rows
from cbp.state import RobotState


@dataclass(frozen=True, kw_only=True)
class JointVelocityParams(PluginParams):
    """Parameters of :class:`JointVelocityConstraint`."""

    scale: float = 1.0
    """Fraction of the robot's velocity limits to allow, in (0, 1]."""
    limits: dict[str, float] = field(default_factory=dict)
    """Velocity limits by joint name that replace the robot's [rad/s or m/s]."""

    def __post_init__(self) -> None:
        """Scale in (0, 1], limits positive."""
        check_scaled_limits(self.scale, self.limits)


class JointVelocityConstraint(
    StepDisplacement[JointVelocityParams], Constraint[JointVelocityParams]
):
    r"""Displacement over one step within the velocity limits.

    .. math:: -s\,v_{max}\,\Delta t \le q \ominus q_0 \le s\,v_{max}\,\Delta t

    where :math:`q_0` is the configuration at the start of the step (latched by
    :meth:`prepare`, which also reads the step duration :math:`\Delta t`).
    Dimension: the tangent coordinates with a finite velocity limit [rad or m].
    With gain 1 (the default) the rows are :math:`|\Delta q_i| \le s\,v_i \Delta t`.
    No singularity.
    """

    type_name: ClassVar[str] = "joint_velocity"
    unit: ClassVar[str] = "rad"
    robot_limit: ClassVar[RobotLimit | None] = "velocity"

    def __init__(
        self, params: JointVelocityParams, robot: RobotModel, name: str = ""
    ) -> None:
        """Gather the limits and keep the coordinates that have one."""
        super().__init__(params, robot, name)
        finite, velocity = limits_by_joint(robot, robot.velocity_limits, params.limits)
        self.rows = compact_rows(finite)
        self._velocity = params.scale * velocity
        self._reach = np.zeros(finite.size)
        self._negative_reach = np.zeros(finite.size)
        self._dt = 0.0

    def prepare(self, state: RobotState, dt: float) -> None:
        """Latch the start configuration and the step duration [s]."""
        super().prepare(state, dt)
        if dt != self._dt:  # the same every step, usually
            self._reach = self._velocity * dt
            self._negative_reach = -self._reach
            # Fixed until dt changes: the engine copies them once.
            self._reach.flags.writeable = False
            self._negative_reach.flags.writeable = False
            self._dt = dt

    def compute_bounds(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """±(scaled velocity limit) x (step duration)."""
        return self._negative_reach, self._reach

    def __repr__(self) -> str:
        """Type, name and scale."""
        return (
            f"JointVelocityConstraint(name={self.name!r}, scale={self.params.scale}, "
            f"limits={self.params.limits!r})"
        )
