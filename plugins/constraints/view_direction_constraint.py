# SPDX-License-Identifier: Apache-2.0
"""Constraint ``view_direction``: the camera looks at the object (eq. 8)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np
import pinocchio as pin

from cbp.orbit import CameraObjectParams, ObjectTarget, frame_of, unit
from cbp.plugin import Constraint, FloatArray
from cbp.robot import RobotModel
from cbp.spatial import cross3
from cbp.state import RobotState


@dataclass(frozen=True, kw_only=True)
class ViewDirectionParams(CameraObjectParams):
    """Parameters of :class:`ViewDirectionConstraint`."""

    form: Literal["image", "paper"] = "image"
    """``image``: the object's direction in the image plane, two rows that vanish
    linearly (well conditioned); ``paper``: eq. 8, one row whose gradient
    vanishes at the solution, so the feedback fades as the error does."""


class ViewDirectionConstraint(Constraint[ViewDirectionParams]):
    r"""The camera's line of sight (its x axis) points at the object's centre.

    With :math:`d = p_o - p_e`, :math:`\hat d = d/\|d\|` and the camera axes
    :math:`x, y, z` (columns of :math:`R_e`), world-aligned Jacobians
    :math:`J_t, J_\omega` of the camera frame:

    * ``form: paper`` (eq. 8, one row, = 0):
      :math:`f_2 = d^T x - \|d\|`,
      :math:`\partial f_2/\partial q = -x^T J_t + (x \times d)^T J_\omega
      + \hat d^T J_t` (eq. 14, re-derived: the angular term is
      :math:`d^T (\omega \times x) = (x \times d)^T \omega`). It is
      :math:`-\|d\|(1 - \cos\theta)`: quadratic in the angle θ, with a zero
      gradient at the solution.
    * ``form: image`` (two rows, = 0): the direction to the object in the
      image plane, :math:`f = (y^T \hat d,\ z^T \hat d)` (the sines of the
      angles off the line of sight), with
      :math:`\partial (a^T \hat d)/\partial q = (a \times \hat d)^T J_\omega
      - a^T \frac{I - \hat d \hat d^T}{\|d\|} J_t` for :math:`a = y, z`.
      Zero also when the camera looks straight away; the orbit starts looking
      at the object.

    Dimension 1 or 2 [m or 1]. Singular when the camera is at the centre.
    """

    type_name: ClassVar[str] = "view_direction"
    unit: ClassVar[str] = "1"

    def __init__(
        self, params: ViewDirectionParams, robot: RobotModel, name: str = ""
    ) -> None:
        """Resolve the frame."""
        super().__init__(params, robot, name)
        self.frame_id = frame_of(robot, params.frame)
        self.object = ObjectTarget(params.object)

    @property
    def dim(self) -> int:
        """Two rows (image) or one (paper)."""
        return 2 if self.params.form == "image" else 1

    def compute_value(self, state: RobotState) -> FloatArray:
        """Image-plane direction, or eq. 8."""
        R = state.frame_rotation(self.frame_id)
        d = self.object.position - state.frame_position(self.frame_id)
        direction, norm = unit(d)
        if self.params.form == "paper":
            return np.array([d.dot(R[:, 0]) - norm])
        return np.array([R[:, 1].dot(direction), R[:, 2].dot(direction)])

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """Exact derivative along tangent directions (see the class docstring)."""
        R = state.frame_rotation(self.frame_id)
        J = state.frame_jacobian(self.frame_id)
        Jt, Jw = J[:3], J[3:]
        d = self.object.position - state.frame_position(self.frame_id)
        direction, norm = unit(d)
        if self.params.form == "paper":
            x = R[:, 0]
            row = -x.dot(Jt) + cross3(x, d).dot(Jw) + direction.dot(Jt)
            return np.asarray(row[None, :])
        projector = (np.eye(3) - np.outer(direction, direction)) / norm
        rows = np.empty((2, J.shape[1]))
        for i, axis in enumerate((R[:, 1], R[:, 2])):
            rows[i] = pin.skew(axis).dot(direction).dot(Jw) - axis.dot(projector).dot(
                Jt
            )
        return rows

    def compute_bounds(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """Zero: an equality when hard."""
        zero = np.zeros(self.dim)
        return zero, zero.copy()

    def angle(self, state: RobotState) -> float:
        """Angle between the line of sight and the direction to the object [rad]."""
        x = state.frame_rotation(self.frame_id)[:, 0]
        d = self.object.position - state.frame_position(self.frame_id)
        direction, _ = unit(d)
        return float(np.arccos(np.clip(x.dot(direction), -1.0, 1.0)))

    def signals(self, state: RobotState) -> dict[str, float]:
        """``view_error_deg``: :meth:`angle` in degrees."""
        return {"view_error_deg": math.degrees(self.angle(state))}
