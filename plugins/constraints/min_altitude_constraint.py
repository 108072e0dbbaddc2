# SPDX-License-Identifier: Apache-2.0
"""Constraint ``min_altitude``: the camera stays high enough over the base (eq. 10)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cbp.orbit import frame_of
from cbp.plugin import Constraint, FloatArray, PluginParams
from cbp.robot import RobotModel
from cbp.spatial import cross3
from cbp.state import RobotState


@dataclass(frozen=True, kw_only=True)
class MinAltitudeParams(PluginParams):
    """Parameters of :class:`MinAltitudeConstraint`."""

    frame: str = "camera_link"
    """The frame kept up."""
    base_frame: str = "base_footprint"
    """Heights are measured along this frame's z axis, from its origin."""
    min_height: float = 0.1
    """z_min [m]."""


class MinAltitudeConstraint(Constraint[MinAltitudeParams]):
    r"""Height of a frame over the base, at least z_min.

    .. math:: f_4 = z_b^T (p_e - p_b) \ge z_{min}, \qquad
              \frac{\partial f_4}{\partial q} = z_b^T (J_{t,e} - J_{t,b})
              + (z_b \times (p_e - p_b))^T J_{\omega,b}

    (eq. 16 with the base's own motion included). Dimension 1 [m]. No
    singularity.
    """

    type_name: ClassVar[str] = "min_altitude"
    unit: ClassVar[str] = "m"

    def __init__(
        self, params: MinAltitudeParams, robot: RobotModel, name: str = ""
    ) -> None:
        """Resolve both frames."""
        super().__init__(params, robot, name)
        self.frame_id = frame_of(robot, params.frame)
        self.base_id = frame_of(robot, params.base_frame)

    @property
    def dim(self) -> int:
        """One row."""
        return 1

    def compute_value(self, state: RobotState) -> FloatArray:
        """z_b . (p_e - p_b)."""
        z_b = state.frame_rotation(self.base_id)[:, 2]
        offset = state.frame_position(self.frame_id) - state.frame_position(
            self.base_id
        )
        return np.array([z_b.dot(offset)])

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """z_b^T (J_t,e - J_t,b) + (z_b x (p_e - p_b))^T J_w,b."""
        z_b = state.frame_rotation(self.base_id)[:, 2]
        offset = state.frame_position(self.frame_id) - state.frame_position(
            self.base_id
        )
        Je = state.frame_jacobian(self.frame_id)
        Jb = state.frame_jacobian(self.base_id)
        row = z_b.dot(Je[:3] - Jb[:3]) + cross3(z_b, offset).dot(Jb[3:])
        return np.asarray(row[None, :])

    def linearize_into(
        self, state: RobotState, value: FloatArray, jacobian: FloatArray
    ) -> None:
        """Value and Jacobian from the same offset."""
        z_b = state.frame_rotation(self.base_id)[:, 2]
        offset = state.frame_position(self.frame_id) - state.frame_position(
            self.base_id
        )
        value[0] = z_b.dot(offset)
        Je = state.frame_jacobian(self.frame_id)
        Jb = state.frame_jacobian(self.base_id)
        jacobian[0] = z_b.dot(Je[:3] - Jb[:3]) + cross3(z_b, offset).dot(Jb[3:])

    def compute_bounds(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """z_min <= f."""
        return np.array([self.params.min_height]), np.array([np.inf])

    def signals(self, state: RobotState) -> dict[str, float]:
        """``altitude`` and its bound ``min_altitude`` [m]."""
        return {
            "altitude": float(self.compute_value(state)[0]),
            "min_altitude": self.params.min_height,
        }
