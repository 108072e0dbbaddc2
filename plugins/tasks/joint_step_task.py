# SPDX-License-Identifier: Apache-2.0
"""Task ``joint_step``: keep each step's joint displacement small (CAT paper, eq. 2)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from cbp.errors import TargetNotSetError
from cbp.plugin import FloatArray, PluginParams, Task
from cbp.robot import RobotModel
from cbp.state import RobotState


@dataclass(frozen=True, kw_only=True)
class JointStepParams(PluginParams):
    """Parameters of :class:`JointStepTask` (none: the weight sets its strength)."""


class JointStepTask(Task[JointStepParams]):
    r"""Displacement from the configuration at the start of the step.

    .. math:: f(q) = q \ominus q_0

    where :math:`q_0` is latched by :meth:`prepare`. Dimension nv, tangent space
    [rad or m]. At the start of the step f = 0 and J = I, so the soft term is
    :math:`\Delta q^T W \Delta q`, the CAT paper's eq. 2, with W = diag(weight),
    whatever the gain. No singularity.
    """

    type_name: ClassVar[str] = "joint_step"
    Params: ClassVar[type[PluginParams]] = JointStepParams
    unit: ClassVar[str] = "rad"

    def __init__(
        self, params: JointStepParams, robot: RobotModel, name: str = ""
    ) -> None:
        """Nothing to resolve."""
        super().__init__(params, robot, name)
        # q ⊖ q_ref has the identity as its Jacobian when nq == nv.
        self.constant_jacobian = robot.is_euclidean
        self._q0: FloatArray | None = None

    @property
    def dim(self) -> int:
        """One row per tangent coordinate."""
        return self.robot.nv

    def prepare(self, state: RobotState, dt: float) -> None:
        """Latch the configuration at the start of the step."""
        self._q0 = state.q

    def _anchor(self) -> FloatArray:
        if self._q0 is None:
            raise TargetNotSetError(
                f"{self.name} ({self.type_name}): prepare() was not called"
            )
        return self._q0

    def compute_value(self, state: RobotState) -> FloatArray:
        """Q ⊖ q0."""
        return self.robot.difference(self._anchor(), state.q)

    def value_into(self, state: RobotState, value: FloatArray) -> None:
        """Q ⊖ q0, written in place."""
        self.robot.difference_into(self._anchor(), state.q, value)

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """Jacobian of q ⊖ q0 (identity on Euclidean joints)."""
        return self.robot.difference_jacobian(self._anchor(), state.q)

    def __repr__(self) -> str:
        """Type and name."""
        return f"JointStepTask(name={self.name!r})"
