# SPDX-License-Identifier: Apache-2.0
"""Poses as written in YAML, and the rotation helpers the plugins share."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from cbp.errors import ConfigError, InvalidTargetError
from cbp.robot import FloatArray


@dataclass(frozen=True, kw_only=True)
class Pose:
    """A pose in the world frame, as written in a scenario.

    The rotation is roll-pitch-yaw in degrees, applied as R = Rz(yaw) Ry(pitch)
    Rx(roll) (fixed axes x, then y, then z).
    """

    position: tuple[float, float, float]
    """Position [m]."""
    rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Roll, pitch, yaw [deg]."""

    def __post_init__(self) -> None:
        """Reject non-finite numbers."""
        if not np.all(np.isfinite(self.position)):
            raise ConfigError("must be finite", location="position")
        if not np.all(np.isfinite(self.rpy_deg)):
            raise ConfigError("must be finite", location="rpy_deg")

    def to_se3(self) -> pin.SE3:
        """Return the pose as a pinocchio SE3."""
        rotation = pin.rpy.rpyToMatrix(*np.deg2rad(self.rpy_deg))
        return pin.SE3(rotation, np.array(self.position, dtype=float))


_ORTHONORMAL_ATOL = 1e-6
_ORTHONORMAL_RTOL = 1e-5
"""How far R^T R may be from the identity: |entry - I| <= atol + rtol |I|."""


def checked_se3(
    position: npt.ArrayLike, rotation: npt.ArrayLike, what: str = "target"
) -> pin.SE3:
    """Build an SE3 from a position (3,) and a rotation matrix (3, 3), checking both.

    Raises:
        InvalidTargetError: wrong shape, not finite, or not a rotation matrix.
    """
    p, R = checked_pose(position, rotation, what)
    return pin.SE3(R, p)


def checked_pose(
    position: npt.ArrayLike, rotation: npt.ArrayLike, what: str = "target"
) -> tuple[FloatArray, FloatArray]:
    """Return copies of a position (3,) and a rotation matrix (3, 3), checked.

    Raises:
        InvalidTargetError: wrong shape, not finite, or not a rotation matrix.
    """
    p = np.array(position, dtype=float)
    R = np.array(rotation, dtype=float)
    if p.shape != (3,) or R.shape != (3, 3):
        raise InvalidTargetError(
            f"{what}: position must have shape (3,) and rotation (3, 3); got "
            f"{p.shape} and {R.shape}"
        )
    # One compiled call (a dozen numpy calls on 3x3 arrays cost more than the
    # whole check, which runs on every goal update); the message after it.
    if checked_pose_into(p, R, np.empty(3), np.empty((3, 3))):
        return p, R
    # A NaN or an infinity makes the sum NaN or infinite (so do finite entries
    # near 1e308, which are no pose either).
    if not math.isfinite(float(p.sum() + R.sum())):
        raise InvalidTargetError(f"{what}: not finite (position {p}, rotation {R})")
    raise InvalidTargetError(f"{what}: rotation is not a rotation matrix: {R}")


@numba.njit(
    "boolean(float64[:], float64[:, :], float64[::1], float64[:, ::1])",
    cache=True,
    nogil=True,
)
def checked_pose_into(
    position: FloatArray,
    rotation: FloatArray,
    translation_out: FloatArray,
    rotation_t_out: FloatArray,
) -> bool:
    """:func:`checked_pose`'s checks in one compiled call, for arrays of floats.

    Writes the position (3,) into ``translation_out`` and the rotation's
    transpose into ``rotation_t_out`` (3, 3), and returns True, when they are a
    pose by the same arithmetic as :func:`checked_pose`; otherwise writes
    nothing and returns False (call :func:`checked_pose` for the message). One
    signature for any memory layout: nothing compiles at run time.
    """
    if position.shape[0] != 3 or rotation.shape[0] != 3 or rotation.shape[1] != 3:
        return False
    x, y, z = position[0], position[1], position[2]
    a, b, c = rotation[0, 0], rotation[0, 1], rotation[0, 2]
    d, e, f = rotation[1, 0], rotation[1, 1], rotation[1, 2]
    g, h, i = rotation[2, 0], rotation[2, 1], rotation[2, 2]
    if not math.isfinite(x + y + z + a + b + c + d + e + f + g + h + i):
        return False
    unit = max(
        abs(a * a + d * d + g * g - 1.0),
        abs(b * b + e * e + h * h - 1.0),
        abs(c * c + f * f + i * i - 1.0),
    )
    orthogonal = max(
        abs(a * b + d * e + g * h),
        abs(a * c + d * f + g * i),
        abs(b * c + e * f + h * i),
    )
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if (
        unit > _ORTHONORMAL_ATOL + _ORTHONORMAL_RTOL
        or orthogonal > _ORTHONORMAL_ATOL
        or det < 0.0
    ):
        return False
    for k in range(3):
        translation_out[k] = position[k]
        for j in range(3):
            rotation_t_out[k, j] = rotation[j, k]
    return True


def cross3(a: FloatArray, b: FloatArray) -> FloatArray:
    """Cross product of two 3-vectors (``np.cross`` costs ~10x more on them)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


@numba.njit(cache=True, nogil=True)
def log3(M: FloatArray) -> tuple[float, float, float, float]:
    r"""The rotation vector w of a rotation matrix, with its angle: (angle, wx, wy, wz).

    :math:`\exp([w]_\times) = M`, angle in [0, π]. Near π the axis comes from
    the symmetric part of M (the antisymmetric part vanishes there); at π
    exactly, either of the two opposite vectors may be returned.
    """
    c = min(max(0.5 * (M[0, 0] + M[1, 1] + M[2, 2] - 1.0), -1.0), 1.0)
    # The antisymmetric part: 2 sin(angle) times the axis.
    ax, ay, az = M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]
    s = 0.5 * math.sqrt(ax * ax + ay * ay + az * az)
    angle = math.atan2(s, c)  # accurate at every angle, unlike acos(c) near π
    if angle < 1e-4:  # angle / (2 sin angle), to second order
        t = 0.5 * (1.0 + angle * angle / 6.0)
        return angle, t * ax, t * ay, t * az
    if angle < math.pi - 1e-3:
        t = 0.5 * angle / s
        return angle, t * ax, t * ay, t * az
    # M + M^T = 2 c I + 2 (1 - c) a a^T: the largest a_k from the diagonal (its
    # sign from the antisymmetric part), the others from row k.
    scale = 1.0 / (1.0 - c)
    d = ((M[0, 0] - c) * scale, (M[1, 1] - c) * scale, (M[2, 2] - c) * scale)
    k = 0 if d[0] >= d[1] and d[0] >= d[2] else (1 if d[1] >= d[2] else 2)
    anti = (ax, ay, az)
    a_k = math.sqrt(max(d[k], 0.0))
    if anti[k] < 0.0:
        a_k = -a_k
    a = [0.0, 0.0, 0.0]
    for j in range(3):
        a[j] = a_k if j == k else 0.5 * (M[k, j] + M[j, k]) * scale / a_k
    return angle, angle * a[0], angle * a[1], angle * a[2]


@numba.njit(cache=True, nogil=True)
def pose_error_into(
    rotation: FloatArray,
    translation: FloatArray,
    goal_rotation_t: FloatArray,
    goal_translation: FloatArray,
    frame_jacobian: FloatArray,
    value: FloatArray,
    jacobian: FloatArray,
) -> None:
    r"""A frame's pose error to a goal, and its Jacobian, written in place.

    With :math:`M = R R_g^T`: ``value`` (6,) is :math:`[p - p_g; \log_3 M]`,
    ``jacobian`` (6, nv) is the frame's world-aligned Jacobian (linear rows
    first) with the angular rows mapped through :math:`J_{\log_3}(M) M^T`,
    :math:`J_{\log_3} = I + \frac12 [w]_\times + \alpha [w]_\times^2`,
    :math:`\alpha = 1/\theta^2 - \cot(\theta/2) / (2\theta)` (to second order
    near 0). Singular at θ = π.
    """
    M = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            M[i, j] = (
                rotation[i, 0] * goal_rotation_t[0, j]
                + rotation[i, 1] * goal_rotation_t[1, j]
                + rotation[i, 2] * goal_rotation_t[2, j]
            )
    for i in range(3):
        value[i] = translation[i] - goal_translation[i]
    angle, wx, wy, wz = log3(M)
    value[3], value[4], value[5] = wx, wy, wz
    if angle < 1e-4:
        alpha = 1.0 / 12.0 + angle * angle / 720.0
    else:
        alpha = 1.0 / (angle * angle) - 0.5 / (angle * math.tan(0.5 * angle))
    # J_log3 with [w]x^2 = w w^T - |w|^2 I, then A = J_log3 M^T.
    W = np.array(((0.0, -wz, wy), (wz, 0.0, -wx), (-wy, wx, 0.0)))
    w2 = wx * wx + wy * wy + wz * wz
    w = (wx, wy, wz)
    J_log = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            J_log[i, j] = 0.5 * W[i, j] + alpha * w[i] * w[j]
        J_log[i, i] += 1.0 - alpha * w2
    A = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            A[i, j] = (
                J_log[i, 0] * M[j, 0] + J_log[i, 1] * M[j, 1] + J_log[i, 2] * M[j, 2]
            )
    nv = frame_jacobian.shape[1]
    for c in range(nv):
        jacobian[0, c] = frame_jacobian[0, c]
        jacobian[1, c] = frame_jacobian[1, c]
        jacobian[2, c] = frame_jacobian[2, c]
        for i in range(3):
            jacobian[3 + i, c] = (
                A[i, 0] * frame_jacobian[3, c]
                + A[i, 1] * frame_jacobian[4, c]
                + A[i, 2] * frame_jacobian[5, c]
            )
