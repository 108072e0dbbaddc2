# SPDX-License-Identifier: Apache-2.0
"""Constraint ``orbit_distance``: the camera stays at r_d from the object (eq. 7)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cbp.errors import ConfigError
from cbp.orbit import CameraObjectParams, ObjectTarget, frame_of, unit
from cbp.plugin import Constraint, FloatArray, InputValue
from cbp.robot import RobotModel
from cbp.state import RobotState


@dataclass(frozen=True, kw_only=True)
class OrbitDistanceParams(CameraObjectParams):
    """Parameters of :class:`OrbitDistanceConstraint`."""

    distance: float = 0.5
    """Desired distance r_d [m]; the operator changes it at run time (input)."""

    def __post_init__(self) -> None:
        """Positive distance."""
        super().__post_init__()
        if not self.distance > 0:
            raise ConfigError(f"must be > 0, got {self.distance}", "distance")


class OrbitDistanceConstraint(Constraint[OrbitDistanceParams]):
    r"""Distance from the camera to the object's centre, equal to r_d.

    .. math:: f_1 = \|p_o - p_e\| = r_d, \qquad
              \frac{\partial f_1}{\partial q} = -\hat d^T J_t

    with :math:`d = p_o - p_e`, :math:`\hat d = d / \|d\|` and :math:`J_t` the
    camera frame's linear Jacobian (world-aligned, arm and base). Dimension 1
    [m]. Singular when the camera is at the centre. Input: ``[r_d]``.

    While r_d moves at a steady rate (the same sign and about the same change
    over the last two steps), :meth:`bound_change` says how far it will move
    over the next one, and an engine step given the robot's velocity follows
    it without the feedback's lag (rate / k); a single jump is left to the
    feedback.
    """

    type_name: ClassVar[str] = "orbit_distance"
    unit: ClassVar[str] = "m"
    input_size: ClassVar[int] = 1

    def __init__(
        self, params: OrbitDistanceParams, robot: RobotModel, name: str = ""
    ) -> None:
        """Resolve the frame; r_d starts at ``distance``."""
        super().__init__(params, robot, name)
        self.frame_id = frame_of(robot, params.frame)
        self.object = ObjectTarget(params.object)
        self.distance = params.distance
        # r_d at the last three steps' starts, newest last.
        self._seen = [params.distance] * 3

    @property
    def dim(self) -> int:
        """One row."""
        return 1

    def set_input(self, values: FloatArray) -> None:
        """Set r_d [m] from the operator's input ``[r_d]``."""
        r = float(values[0])
        if not r > 0:
            raise ValueError(f"r_d must be > 0, got {r}")
        self.distance = r

    def input_values(self) -> tuple[InputValue, ...]:
        """The desired distance r_d [m]: from 0.1 m to twice the starting one."""
        return (
            InputValue(
                "distance to the object (r_d)",
                "m",
                0.1,
                max(2.0 * self.params.distance, 1.0),
            ),
        )

    def prepare(self, state: RobotState, dt: float) -> None:
        """Note r_d at the step's start."""
        self._seen = [*self._seen[1:], self.distance]

    def bound_change(self) -> FloatArray:
        """The change of r_d kept over the last two steps [m]; 0 if it was not."""
        older, old, new = self._seen
        now, before = new - old, old - older
        if now * before <= 0.0:
            return np.zeros(1)
        return np.array([math.copysign(min(abs(now), abs(before)), now)])

    def compute_value(self, state: RobotState) -> FloatArray:
        """||p_o - p_e||."""
        d = self.object.position - state.frame_position(self.frame_id)
        return np.array([math.sqrt(d.dot(d))])

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """-d̂^T J_t."""
        d = self.object.position - state.frame_position(self.frame_id)
        direction, _ = unit(d)
        return np.asarray(
            -direction.dot(state.frame_jacobian(self.frame_id)[:3])[None, :]
        )

    def linearize_into(
        self, state: RobotState, value: FloatArray, jacobian: FloatArray
    ) -> None:
        """Value and Jacobian from one difference d."""
        d = self.object.position - state.frame_position(self.frame_id)
        direction, norm = unit(d)
        value[0] = norm
        jacobian[0] = -direction.dot(state.frame_jacobian(self.frame_id)[:3])

    def compute_bounds(self, state: RobotState) -> tuple[FloatArray, FloatArray]:
        """r_d <= f <= r_d (an equality when hard)."""
        r = np.array([self.distance])
        return r, r.copy()

    def signals(self, state: RobotState) -> dict[str, float]:
        """``distance`` and ``distance_desired`` (r_d) [m]."""
        return {
            "distance": float(self.compute_value(state)[0]),
            "distance_desired": self.distance,
        }
