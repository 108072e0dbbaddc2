# SPDX-License-Identifier: Apache-2.0
r"""Joint-space terms: rows of the tangent difference to a reference configuration.

:class:`JointDifference` is the base of ``posture``, ``joint_step`` and
``joint_velocity``: f(q) = S (q ⊖ q_ref), with S selecting tangent rows. It
writes the engine's rows in place and, on a Euclidean model, declares its
Jacobian constant (the identity rows), so the engine linearizes it once. A
subclass says what the reference is (:meth:`JointDifference.reference`) and
which rows it keeps (``rows``); :class:`StepDisplacement` anchors the reference
at the start of each step.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping

import numpy as np

from cbp.errors import ConfigError, located
from cbp.plugin import FloatArray, ParamsT, Plugin
from cbp.robot import IndexRows, IntArray, RobotModel, rows_count
from cbp.state import RobotState

__all__ = [
    "JointDifference",
    "StepDisplacement",
    "check_scaled_limits",
    "limits_by_joint",
]


class JointDifference(Plugin[ParamsT]):
    r"""f(q) = S (q ⊖ q_ref): selected rows of the tangent difference to q_ref.

    Dimension: the number of selected rows [rad or m]. Jacobian:
    :math:`S\,\partial (q \ominus q_{ref})/\partial q`, the identity rows when
    ``nq == nv``. No singularity.

    Attributes:
        rows: the tangent rows kept (a slice or an index array; default all).
    """

    def __init__(self, params: ParamsT, robot: RobotModel, name: str = "") -> None:
        """Keep every tangent row; subclasses narrow ``rows``."""
        super().__init__(params, robot, name)
        self.rows: IndexRows = slice(0, robot.nv)
        self._every_row = self.rows
        # q ⊖ q_ref has the identity as its Jacobian when nq == nv.
        self.constant_jacobian = robot.is_euclidean

    @abc.abstractmethod
    def reference(self) -> FloatArray:
        """The reference configuration q_ref (nq)."""

    @property
    def dim(self) -> int:
        """One row per selected tangent coordinate."""
        return rows_count(self.rows, self.robot.nv)

    def compute_value(self, state: RobotState) -> FloatArray:
        """Selected rows of q ⊖ q_ref."""
        return self.robot.difference(self.reference(), state.q)[self.rows]

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """Selected rows of the Jacobian of q ⊖ q_ref."""
        return self.robot.difference_jacobian(self.reference(), state.q, self.rows)

    def value_into(self, state: RobotState, value: FloatArray) -> None:
        """Selected rows of q ⊖ q_ref, written in place."""
        rows = self.rows
        if type(rows) is slice and rows == self._every_row and self.robot.is_euclidean:
            np.subtract(state.q, self.reference(), out=value)  # every row: q - q_ref
            return
        self.robot.difference_into(self.reference(), state.q, value, rows)


class StepDisplacement(JointDifference[ParamsT]):
    r"""f(q) = S (q ⊖ q_0), q_0 the configuration at the start of the step.

    :meth:`prepare` latches q_0; evaluating before it raises
    :class:`~cbp.errors.TargetNotSetError`.
    """

    def __init__(self, params: ParamsT, robot: RobotModel, name: str = "") -> None:
        """No anchor until the first step."""
        super().__init__(params, robot, name)
        self._q0: FloatArray | None = None

    def prepare(self, state: RobotState, dt: float) -> None:
        """Latch the configuration at the start of the step."""
        self._q0 = state.q

    def reference(self) -> FloatArray:
        """The configuration at the start of the step."""
        return self.latched(self._q0)

    def value_into(self, state: RobotState, value: FloatArray) -> None:
        """Selected rows of q ⊖ q_0, written in place.

        At the state :meth:`prepare` latched, on a Euclidean model, that is
        q - q: zeros, written without the arithmetic (the engine's every step;
        it has checked q finite).
        """
        if self._q0 is state.q and self.robot.is_euclidean:
            value.fill(0.0)
            return
        super().value_into(state, value)


def check_scaled_limits(scale: float, limits: Mapping[str, float]) -> None:
    """A limit plugin's parameters: ``scale`` in (0, 1], every limit positive.

    Raises:
        ConfigError: located at ``scale`` or ``limits.<joint>``.
    """
    if not 0 < scale <= 1:
        raise ConfigError(f"must be in (0, 1], got {scale}", "scale")
    for joint, value in limits.items():
        if not value > 0:
            raise ConfigError(f"must be > 0, got {value}", f"limits.{joint}")


def limits_by_joint(
    robot: RobotModel, robot_limits: FloatArray, limits: Mapping[str, float]
) -> tuple[IntArray, FloatArray]:
    """The tangent coordinates with a finite limit, and those limits.

    ``robot_limits`` (nv) with ``limits`` by joint name put in their place
    (an unknown joint is a ConfigError located at ``limits.<joint>``).
    """
    values = np.array(robot_limits, dtype=float)
    for joint, value in limits.items():
        values[located(robot.joint_v_slice, joint, f"limits.{joint}")] = value
    finite = np.flatnonzero(np.isfinite(values))
    return finite, values[finite]
