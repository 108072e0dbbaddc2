# SPDX-License-Identifier: Apache-2.0
"""Constraint ``joint_limits``: keep joints inside their position limits (eq. 4)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cbp.errors import ConfigError, located
from cbp.plugin import Constraint, FloatArray, PluginParams, RobotLimit
from cbp.robot import RobotModel, compact_rows
from cbp.state import RobotState


@dataclass(frozen=True, kw_only=True)
class JointLimitsParams(PluginParams):
    """Parameters of :class:`JointLimitsConstraint`."""

    margin: float = 0.0
    """Distance kept from each limit [rad or m]."""
    joints: list[str] | None = None
    """Joints to limit; default every joint with a finite range."""

    def __post_init__(self) -> None:
        """The margin cannot be negative."""
        if not self.margin >= 0:
            raise ConfigError(f"must be >= 0, got {self.margin}", "margin")


class JointLimitsConstraint(Constraint[JointLimitsParams]):
    r"""Positions of the joints with a finite range, within their limits.

    .. math:: q_{min} + m \le q_i \le q_{max} - m

    Dimension: the number of limited joints [rad or m]. The Jacobian selects
    their tangent coordinates. With gain 1 (the default) the QP rows are exactly
    CAT's eq. 4, :math:`q_{min} \le q + \Delta q \le q_{max}`; a smaller gain
    approaches a limit exponentially. No singularity.
    """

    type_name: ClassVar[str] = "joint_limits"
    unit: ClassVar[str] = "rad"
    robot_limit: ClassVar[RobotLimit | None] = "position"
    constant_jacobian = True  # a selection of tangent coordinates

    def __init__(
        self, params: JointLimitsParams, robot: RobotModel, name: str = ""
    ) -> None:
        """Pick the bounded coordinates and check the margin fits every range."""
        super().__init__(params, robot, name)
        q_idx, v_idx = robot.bounded_q, robot.bounded_v
        if params.joints is not None:
            wanted = located(robot.joint_v_indices, params.joints, "joints")
            unbounded = [
                j for j, v in zip(params.joints, wanted, strict=False) if v not in v_idx
            ]
            if unbounded:
                raise ConfigError(
                    f"joints without a finite range cannot be limited: "
                    f"{', '.join(unbounded)}",
                    "joints",
                )
            keep = np.isin(v_idx, wanted)
            q_idx, v_idx = q_idx[keep], v_idx[keep]
        self.q_idx, self.v_idx = q_idx, v_idx
        self._q_rows = compact_rows(q_idx)  # a slice when consecutive
        self._lower = robot.lower_limits[q_idx] + params.margin
        self._upper = robot.upper_limits[q_idx] - params.margin
        short = np.flatnonzero(self._lower > self._upper)
        if short.size:
            names = robot.coordinate_names("q")
            ranges = ", ".join(
                f"{names[q_idx[i]]} [{robot.lower_limits[q_idx[i]]:g}, "
                f"{robot.upper_limits[q_idx[i]]:g}]"
                for i in short
            )
            source = f" ({robot.source})" if robot.source is not None else ""
            raise ConfigError(
                f"margin {params.margin:g} is more than half the range of "
                f"{ranges} of robot '{robot.name}'{source}: lock the joint "
                "(robot.yaml's locked_joints), limit other joints (params.joints) "
                "or set a smaller margin",
                "margin",
            )
        self._J = np.zeros((q_idx.size, robot.nv))
        self._J[np.arange(q_idx.size), v_idx] = 1.0
        for array in (self._lower, self._upper, self._J):
            array.flags.writeable = False

    @property
    def dim(self) -> int:
        """One row per limited joint."""
        return int(self.q_idx.size)

    def compute_value(self, state: RobotState) -> FloatArray:
        """Positions of the limited joints."""
        return state.q[self.q_idx]

    def value_into(self, state: RobotState, value: FloatArray) -> None:
        """Positions of the limited joints, written in place."""
        value[:] = state.q[self._q_rows]

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """Selection of the limited joints' tangent coordinates (read-only)."""
        return self._J

    def compute_bounds(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """Limits shrunk by the margin."""
        return self._lower, self._upper

    def __repr__(self) -> str:
        """Type, name, margin and joints."""
        p = self.params
        return (
            f"JointLimitsConstraint(name={self.name!r}, margin={p.margin}, "
            f"joints={p.joints!r})"
        )
