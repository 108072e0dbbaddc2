# SPDX-License-Identifier: Apache-2.0
"""Camera and object geometry shared by the orbit-object plugins (orbit paper)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from cbp.errors import ConfigError, located
from cbp.plugin import FloatArray, PluginParams
from cbp.robot import RobotModel


@dataclass(frozen=True, kw_only=True)
class CameraObjectParams(PluginParams):
    """A camera frame and the object it looks at."""

    frame: str = "camera_link"
    """Camera frame; its x axis is the line of sight."""
    object: tuple[float, float, float] = (1.0, 0.0, 0.1)
    """Object centre in the world [m] (from the scenario or the depth camera)."""

    def __post_init__(self) -> None:
        """The object position is finite."""
        if not np.all(np.isfinite(self.object)):
            raise ConfigError(f"must be finite, got {list(self.object)}", "object")


class ObjectTarget:
    """The object's position, settable at run time (e.g. from the depth camera)."""

    def __init__(self, position: npt.ArrayLike) -> None:
        """Start at ``position``."""
        self.position = np.array(position, dtype=float)

    def set(self, position: npt.ArrayLike) -> None:
        """Move the object to ``position`` (3,) [m]; NaN or wrong shape is refused."""
        p = np.asarray(position, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"object position must be 3 finite numbers, got {p}")
        self.position = p.copy()


def frame_of(robot: RobotModel, name: str) -> int:
    """Frame id, with the error located at ``frame``."""
    return located(robot.frame_id, name, "frame")


def unit(v: FloatArray) -> tuple[FloatArray, float]:
    """(v / |v|, |v|); raises on a zero vector (the value is not differentiable)."""
    n = math.sqrt(v.dot(v))
    if n < 1e-12:
        raise ZeroDivisionError("the camera is at the object's centre")
    return v / n, n
