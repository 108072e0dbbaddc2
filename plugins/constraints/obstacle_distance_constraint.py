# SPDX-License-Identifier: Apache-2.0
"""Constraint ``obstacle_distance``: the base keeps away from an obstacle (eq. 11)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cbp.errors import ConfigError
from cbp.orbit import frame_of, unit
from cbp.plugin import Constraint, FloatArray, PluginParams
from cbp.robot import RobotModel
from cbp.state import RobotState


@dataclass(frozen=True, kw_only=True)
class ObstacleDistanceParams(PluginParams):
    """Parameters of :class:`ObstacleDistanceConstraint`."""

    frame: str = "base_footprint"
    """The frame kept away (the base's centre)."""
    obstacle: tuple[float, float, float] = (1.0, 0.0, 0.0)
    """Obstacle point in the world [m]."""
    min_distance: float = 0.5
    """r_r [m]."""
    planar: bool = True
    """Measure in the floor plane (x, y), as for a base on the floor."""

    def __post_init__(self) -> None:
        """Finite point, positive distance."""
        if not np.all(np.isfinite(self.obstacle)):
            raise ConfigError(f"must be finite, got {list(self.obstacle)}", "obstacle")
        if not self.min_distance > 0:
            raise ConfigError(f"must be > 0, got {self.min_distance}", "min_distance")


class ObstacleDistanceConstraint(Constraint[ObstacleDistanceParams]):
    r"""Distance from a frame's origin to an obstacle point, at least r_r.

    .. math:: f_5 = \|P (p_b - p_{obs})\| \ge r_r, \qquad
              \frac{\partial f_5}{\partial q} = \hat g^T P J_{t,b}

    with :math:`P` the projection on the floor plane (or the identity with
    ``planar: false``) and :math:`\hat g` the unit vector of
    :math:`P (p_b - p_{obs})` (eq. 17). Dimension 1 [m]. Singular at the
    obstacle point itself.
    """

    type_name: ClassVar[str] = "obstacle_distance"
    unit: ClassVar[str] = "m"

    def __init__(
        self, params: ObstacleDistanceParams, robot: RobotModel, name: str = ""
    ) -> None:
        """Resolve the frame."""
        super().__init__(params, robot, name)
        self.frame_id = frame_of(robot, params.frame)
        self.obstacle = np.array(params.obstacle, dtype=float)
        self._project = np.diag([1.0, 1.0, 0.0 if params.planar else 1.0])

    @property
    def dim(self) -> int:
        """One row."""
        return 1

    def _gap(self, state: RobotState) -> FloatArray:
        return np.asarray(
            self._project.dot(state.frame_position(self.frame_id) - self.obstacle)
        )

    def compute_value(self, state: RobotState) -> FloatArray:
        """||P (p_b - p_obs)||."""
        gap = self._gap(state)
        return np.array([math.sqrt(gap.dot(gap))])

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """ĝ^T P J_t,b."""
        direction, _ = unit(self._gap(state))
        J = state.frame_jacobian(self.frame_id)[:3]
        return np.asarray(direction.dot(self._project).dot(J)[None, :])

    def linearize_into(
        self, state: RobotState, value: FloatArray, jacobian: FloatArray
    ) -> None:
        """Value and Jacobian from one gap."""
        direction, norm = unit(self._gap(state))
        value[0] = norm
        J = state.frame_jacobian(self.frame_id)[:3]
        jacobian[0] = direction.dot(self._project).dot(J)

    def compute_bounds(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """r_r <= f."""
        return np.array([self.params.min_distance]), np.array([np.inf])

    def signals(self, state: RobotState) -> dict[str, float]:
        """``obstacle_distance`` and its bound ``min_obstacle_distance`` [m]."""
        return {
            "obstacle_distance": float(self.compute_value(state)[0]),
            "min_obstacle_distance": self.params.min_distance,
        }
