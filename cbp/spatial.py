# SPDX-License-Identifier: Apache-2.0
"""Poses as written in YAML, and the rotation helpers the plugins share."""

from __future__ import annotations

import math
from dataclasses import dataclass

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
    # Scalar arithmetic: this runs on every goal update, where a dozen numpy
    # calls on 3x3 arrays cost more than the whole check.
    x, y, z = p.tolist()
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    # A NaN or an infinity makes the sum NaN or infinite (so do finite entries
    # near 1e308, which are no pose either).
    if not math.isfinite(x + y + z + a + b + c + d + e + f + g + h + i):
        raise InvalidTargetError(f"{what}: not finite (position {p}, rotation {R})")
    # Columns orthonormal (R^T R = I, as numpy's allclose(atol=1e-6) would judge
    # it) and det R = +1.
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
        raise InvalidTargetError(f"{what}: rotation is not a rotation matrix: {R}")
    return p, R


def cross3(a: FloatArray, b: FloatArray) -> FloatArray:
    """Cross product of two 3-vectors (``np.cross`` costs ~10x more on them)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])
