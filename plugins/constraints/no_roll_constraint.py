# SPDX-License-Identifier: Apache-2.0
"""Constraint ``no_roll``: no rotation about the line of sight (eq. 9)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cbp.orbit import frame_of
from cbp.plugin import Constraint, FloatArray, PluginParams
from cbp.robot import RobotModel
from cbp.spatial import cross3
from cbp.state import RobotState


@dataclass(frozen=True, kw_only=True)
class NoRollParams(PluginParams):
    """Parameters of :class:`NoRollConstraint`."""

    frame: str = "camera_link"
    """Camera frame (x: line of sight, y: the image's horizontal axis)."""
    base_frame: str = "base_link"
    """Frame whose z axis is "up"."""


class NoRollConstraint(Constraint[NoRollParams]):
    r"""The camera's y axis stays horizontal with respect to the base.

    .. math:: f_3 = z_b^T y_e = 0, \qquad
              \frac{\partial f_3}{\partial q} =
              (z_b \times y_e)^T (J_{\omega,b} - J_{\omega,e})

    (eq. 15, re-derived with both frames moving: a planar or floating base
    turns :math:`z_b` too). Dimension 1 [1]: the sine of the image's roll. No
    singularity; zero also when the camera looks straight up or down.
    """

    type_name: ClassVar[str] = "no_roll"
    unit: ClassVar[str] = "1"

    def __init__(self, params: NoRollParams, robot: RobotModel, name: str = "") -> None:
        """Resolve both frames."""
        super().__init__(params, robot, name)
        self.frame_id = frame_of(robot, params.frame)
        self.base_id = frame_of(robot, params.base_frame)

    @property
    def dim(self) -> int:
        """One row."""
        return 1

    def compute_value(self, state: RobotState) -> FloatArray:
        """z_b . y_e."""
        z_b = state.frame_rotation(self.base_id)[:, 2]
        y_e = state.frame_rotation(self.frame_id)[:, 1]
        return np.array([z_b.dot(y_e)])

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """(z_b x y_e)^T (J_w,b - J_w,e)."""
        z_b = state.frame_rotation(self.base_id)[:, 2]
        y_e = state.frame_rotation(self.frame_id)[:, 1]
        Jb = state.frame_jacobian(self.base_id)[3:]
        Je = state.frame_jacobian(self.frame_id)[3:]
        return np.asarray(cross3(z_b, y_e).dot(Jb - Je)[None, :])

    def linearize_into(
        self, state: RobotState, value: FloatArray, jacobian: FloatArray
    ) -> None:
        """Value and Jacobian from the same two axes."""
        z_b = state.frame_rotation(self.base_id)[:, 2]
        y_e = state.frame_rotation(self.frame_id)[:, 1]
        value[0] = z_b.dot(y_e)
        Jb = state.frame_jacobian(self.base_id)[3:]
        Je = state.frame_jacobian(self.frame_id)[3:]
        jacobian[0] = cross3(z_b, y_e).dot(Jb - Je)

    def compute_bounds(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """Zero: an equality when hard."""
        return np.zeros(1), np.zeros(1)

    def roll(self, state: RobotState) -> float:
        """Roll of the image about the line of sight [rad]."""
        return float(np.arcsin(np.clip(self.compute_value(state)[0], -1.0, 1.0)))

    def signals(self, state: RobotState) -> dict[str, float]:
        """``roll_deg``: :meth:`roll` in degrees."""
        return {"roll_deg": math.degrees(self.roll(state))}
