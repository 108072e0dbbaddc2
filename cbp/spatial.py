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


def checked_se3(
    position: npt.ArrayLike, rotation: npt.ArrayLike, what: str = "target"
) -> pin.SE3:
    """Build an SE3 from a position (3,) and a rotation matrix (3, 3), checking both.

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
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(R))):
        raise InvalidTargetError(f"{what}: not finite (position {p}, rotation {R})")
    if not np.allclose(R.T.dot(R), np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise InvalidTargetError(f"{what}: rotation is not a rotation matrix: {R}")
    return pin.SE3(R, p)


def clip_norm(vector: FloatArray, limit: float) -> FloatArray:
    """Return ``vector`` scaled down to norm ``limit`` if it is longer."""
    norm = math.sqrt(vector.dot(vector))
    return vector * (limit / norm) if norm > limit else vector
