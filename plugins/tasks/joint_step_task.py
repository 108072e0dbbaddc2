# SPDX-License-Identifier: Apache-2.0
"""Task ``joint_step``: keep each step's joint displacement small (CAT paper, eq. 2)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from cbp.joint_space import StepDisplacement
from cbp.plugin import PluginParams, Task


@dataclass(frozen=True, kw_only=True)
class JointStepParams(PluginParams):
    """Parameters of :class:`JointStepTask` (none: the weight sets its strength)."""


class JointStepTask(StepDisplacement[JointStepParams], Task[JointStepParams]):
    r"""Displacement from the configuration at the start of the step.

    .. math:: f(q) = q \ominus q_0

    where :math:`q_0` is latched by :meth:`prepare`. Dimension nv, tangent space
    [rad or m]. At the start of the step f = 0 and J = I, so the soft term is
    :math:`\Delta q^T W \Delta q`, the CAT paper's eq. 2, with W = diag(weight),
    whatever the gain. No singularity.
    """

    type_name: ClassVar[str] = "joint_step"
    unit: ClassVar[str] = "rad"

    def __repr__(self) -> str:
        """Type and name."""
        return f"JointStepTask(name={self.name!r})"
