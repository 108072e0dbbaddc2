# SPDX-License-Identifier: Apache-2.0
"""Task ``posture``: pull joints toward a posture (CAT paper, eq. 3)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy.typing as npt

from cbp.errors import located
from cbp.joint_space import JointDifference
from cbp.plugin import FloatArray, PluginParams, Task
from cbp.robot import RobotModel, compact_rows


@dataclass(frozen=True, kw_only=True)
class PostureParams(PluginParams):
    """Parameters of :class:`PostureTask`."""

    target: dict[str, float] | None = None
    """Target position by joint name [rad or m]; joints left out take the middle of
    their range (the neutral where unbounded)."""
    joints: list[str] | None = None
    """Joints the task acts on; default every joint but a mobile base's root."""


class PostureTask(JointDifference[PostureParams], Task[PostureParams]):
    r"""Tangent-space difference between the configuration and a target posture.

    .. math:: f(q) = S\,(q \ominus q_d)

    with S selecting the rows of ``joints``. Dimension: the tangent dimension of
    those joints [rad or m]. Jacobian: :math:`S\,\partial (q \ominus q_d)/\partial q`
    (the identity on revolute and prismatic joints). With the default target, the
    middle of the joint ranges, this is the CAT paper's "passive" posture term
    that biases joints away from their limits. No singularity.
    """

    type_name: ClassVar[str] = "posture"
    unit: ClassVar[str] = "rad"

    def __init__(
        self, params: PostureParams, robot: RobotModel, name: str = ""
    ) -> None:
        """Resolve joint names and build the target configuration."""
        super().__init__(params, robot, name)
        if params.joints is None:
            self.rows = robot.articulated_v_indices()
        else:
            self.rows = compact_rows(
                located(robot.joint_v_indices, params.joints, "joints")
            )
        q_target = robot.middle()
        for joint, value in (params.target or {}).items():
            sl = located(robot.joint_q_slice, joint, f"target.{joint}")
            q_target[sl] = value
        self._target = robot.check_configuration(q_target, "posture target")

    def set_target(self, q_target: npt.ArrayLike) -> None:
        """Set the target configuration (nq), e.g. an IK solution to move toward.

        Raises:
            ConfigError: wrong size or not finite; the target is kept.
        """
        self._target = self.robot.check_configuration(q_target, f"{self.name} target")

    @property
    def target(self) -> FloatArray:
        """The target configuration (nq)."""
        return self._target

    def reference(self) -> FloatArray:
        """The target configuration."""
        return self._target

    def __repr__(self) -> str:
        """Type, name and selected joints."""
        return f"PostureTask(name={self.name!r}, joints={self.params.joints!r})"
