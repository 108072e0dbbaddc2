# SPDX-License-Identifier: Apache-2.0
"""Constraint ``view_direction``: the camera looks at the object (eq. 8)."""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import ClassVar, Literal

import numba
import numpy as np

from cbp.orbit import CameraObjectParams, ObjectTarget, frame_of, unit
from cbp.plugin import Constraint, FloatArray
from cbp.robot import RobotModel
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
        # Compile the rows (or load them from numba's cache) now, on arrays of
        # the kinds a step passes, rather than in the first control step.
        with contextlib.suppress(ZeroDivisionError):
            self.linearize(RobotState(robot))

    @property
    def dim(self) -> int:
        """Two rows (image) or one (paper)."""
        return 2 if self.params.form == "image" else 1

    def compute_value(self, state: RobotState) -> FloatArray:
        """Image-plane direction, or eq. 8."""
        value = np.empty(self.dim)
        self._rows(state, value, _NO_JACOBIAN, _NO_ROWS)
        return value

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """Exact derivative along tangent directions (see the class docstring)."""
        jacobian = np.empty((self.dim, self.robot.nv))
        J = state.frame_jacobian(self.frame_id)
        self._rows(state, np.empty(self.dim), J, jacobian)
        return jacobian

    def linearize_into(
        self, state: RobotState, value: FloatArray, jacobian: FloatArray
    ) -> None:
        """Value and Jacobian in one compiled call, sharing the geometry."""
        J = state.frame_jacobian(self.frame_id)
        self._rows(state, value, J, jacobian)

    def _rows(
        self,
        state: RobotState,
        value: FloatArray,
        J: FloatArray,
        jacobian: FloatArray,
    ) -> None:
        """:func:`_view_rows` at ``state``; the Jacobian only if ``J`` has columns."""
        frame = self.frame_id
        if not _view_rows(
            state.frame_rotation(frame),
            state.frame_position(frame),
            self.object.position,
            J,
            self.params.form == "image",
            value,
            jacobian,
        ):
            raise ZeroDivisionError("the camera is at the object's centre")

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


#: The frame Jacobian and the rows' Jacobian passed when only the value is
#: wanted (no columns: neither is read). Read-only and writeable as a state's
#: frame Jacobian and the engine's rows are: the kernel compiles once.
_NO_JACOBIAN = np.zeros((0, 0))
_NO_JACOBIAN.flags.writeable = False
_NO_ROWS = np.zeros((0, 0))


@numba.njit(cache=True, nogil=True)
def _view_rows(
    R: FloatArray,
    p: FloatArray,
    centre: FloatArray,
    J: FloatArray,
    image: bool,
    value: FloatArray,
    jacobian: FloatArray,
) -> bool:
    """The rows' value and, if ``J`` has columns, Jacobian (class docstring).

    ``R``, ``p``: the camera's rotation and position; ``J`` its world-aligned
    Jacobian (6, nv). False (nothing written) when the camera is at the
    centre.
    """
    d0, d1, d2 = centre[0] - p[0], centre[1] - p[1], centre[2] - p[2]
    norm = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if norm < 1e-12:
        return False
    u0, u1, u2 = d0 / norm, d1 / norm, d2 / norm
    nv = J.shape[1]
    if not image:
        value[0] = d0 * R[0, 0] + d1 * R[1, 0] + d2 * R[2, 0] - norm
        x0, x1, x2 = R[0, 0], R[1, 0], R[2, 0]
        c0, c1, c2 = x1 * d2 - x2 * d1, x2 * d0 - x0 * d2, x0 * d1 - x1 * d0
        for c in range(nv):
            jacobian[0, c] = (
                (u0 - x0) * J[0, c]
                + (u1 - x1) * J[1, c]
                + (u2 - x2) * J[2, c]
                + c0 * J[3, c]
                + c1 * J[4, c]
                + c2 * J[5, c]
            )
        return True
    # The direction's cosines with the camera's axes x, y, z.
    cosines = np.empty(3)
    for i in range(3):
        cosines[i] = R[0, i] * u0 + R[1, i] * u1 + R[2, i] * u2
    cosine, s0, s1 = cosines[0], cosines[1], cosines[2]
    g, h = _angle_scale(math.hypot(s0, s1), cosine)
    value[0], value[1] = g * s0, g * s1
    if nv == 0:
        return True
    # d(a^T d̂)/dq = (a x d̂)^T J_w - a^T (I - d̂ d̂^T) / |d| J_t, a = x, y, z.
    axes = np.empty((3, nv))
    for i in range(3):
        a0, a1, a2 = R[0, i], R[1, i], R[2, i]
        w0, w1, w2 = a1 * u2 - a2 * u1, a2 * u0 - a0 * u2, a0 * u1 - a1 * u0
        t0 = (a0 - cosines[i] * u0) / norm
        t1 = (a1 - cosines[i] * u1) / norm
        t2 = (a2 - cosines[i] * u2) / norm
        for c in range(nv):
            axes[i, c] = (
                w0 * J[3, c]
                + w1 * J[4, c]
                + w2 * J[5, c]
                - t0 * J[0, c]
                - t1 * J[1, c]
                - t2 * J[2, c]
            )
    # d(g s) = g ds + s g'(θ) dθ, dθ = (cos θ s^T ds / |s| - |s| dc), and
    # g'(θ) / |s| = h.
    s2 = s0 * s0 + s1 * s1
    for c in range(nv):
        d_theta = cosine * (s0 * axes[1, c] + s1 * axes[2, c]) - s2 * axes[0, c]
        jacobian[0, c] = g * axes[1, c] + h * s0 * d_theta
        jacobian[1, c] = g * axes[2, c] + h * s1 * d_theta
    return True


@numba.njit(cache=True, nogil=True)
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
