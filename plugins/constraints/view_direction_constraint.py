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
      image plane, as long as the angle θ off the line of sight:
      :math:`f = \theta\, s / \|s\|` with :math:`s = (y^T \hat d,\ z^T \hat d)`
      (the sines of the angles off the line of sight, :math:`\|s\| = \sin\theta`)
      and :math:`\theta = \operatorname{atan2}(\|s\|, x^T \hat d)`; with
      :math:`\partial (a^T \hat d)/\partial q = (a \times \hat d)^T J_\omega
      - a^T \frac{I - \hat d \hat d^T}{\|d\|} J_t` for :math:`a = x, y, z`.
      Its rows vanish linearly at the solution (like :math:`s`, to which they
      tend there), and only there: :math:`s` alone vanishes also when the
      camera looks straight away, where a camera that starts more than 90 deg
      off would settle.

    Dimension 1 or 2 [m or rad]. Singular when the camera is at the centre, and
    (image) when it looks straight away from it.
    """

    type_name: ClassVar[str] = "view_direction"
    unit: ClassVar[str] = "rad"

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
        sine = np.array([R[:, 1].dot(direction), R[:, 2].dot(direction)])
        return _angle_scale(float(np.hypot(*sine)), R[:, 0].dot(direction))[0] * sine

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
        axes = np.empty((3, J.shape[1]))  # d(a^T d̂)/dq for a = x, y, z
        for i in range(3):
            axis = R[:, i]
            axes[i] = pin.skew(axis).dot(direction).dot(Jw) - axis.dot(projector).dot(
                Jt
            )
        sine = R[:, 1:].T.dot(direction)
        cosine = R[:, 0].dot(direction)
        g, h = _angle_scale(float(np.hypot(*sine)), cosine)
        # d(g s) = g ds + s g'(θ) dθ, dθ = (cos θ s^T ds / |s| - |s| dc), and
        # g'(θ) / |s| = h.
        d_theta_scaled = cosine * sine.dot(axes[1:]) - sine.dot(sine) * axes[0]
        return np.asarray(g * axes[1:] + h * np.outer(sine, d_theta_scaled))

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


def _angle_scale(sine: float, cosine: float) -> tuple[float, float]:
    """(θ / sin θ, (θ / sin θ)' / sin θ) for θ = atan2(sine, cosine), sine >= 0.

    Series near θ = 0, where both differences cancel: 1 + θ²/6 and
    1/3 + 2θ²/15.
    """
    theta = math.atan2(sine, cosine)
    if theta < 1e-3:
        t2 = theta * theta
        return 1.0 + t2 / 6.0, 1.0 / 3.0 + 2.0 * t2 / 15.0
    return theta / sine, (sine - theta * cosine) / sine**3
