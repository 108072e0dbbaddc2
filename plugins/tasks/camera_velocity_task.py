# SPDX-License-Identifier: Apache-2.0
"""Task ``camera_velocity``: the camera moves as the operator asks (eq. 12)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from cbp.orbit import frame_of
from cbp.plugin import FloatArray, InputValue, PluginParams, Task
from cbp.robot import RobotModel
from cbp.state import RobotState


@dataclass(frozen=True, kw_only=True)
class CameraVelocityParams(PluginParams):
    """Parameters of :class:`CameraVelocityTask`."""

    frame: str = "camera_link"
    """Camera frame."""
    axes: tuple[int, ...] = (1, 2)
    """Camera axes commanded (0 x: along the line of sight, 1 y, 2 z): the orbit
    commands y and z (the distance is ``orbit_distance``'s); pan object all three."""


#: What each camera axis's velocity moves the camera along.
AXIS_MEANING = ("forward, along its line of sight (x)", "sideways (y)", "up (z)")
#: The fastest camera velocity an operator's slider or stick asks for [m/s].
OPERATOR_SPEED = 0.3


class CameraVelocityTask(Task[CameraVelocityParams]):
    r"""Velocity of the camera along its own axes, as commanded.

    Over a step of duration :math:`\Delta t` from the camera pose
    :math:`(R_a, p_a)` at the step's start (latched by :meth:`prepare`):

    .. math:: f_6 = S R_a^T (p_e - p_a) - v_d \Delta t, \qquad
              \frac{\partial f_6}{\partial q} = S R_a^T J_t

    where :math:`S` selects the commanded axes and :math:`v_d` is the input
    [m/s]. With gain 1 the step asks for exactly :math:`v_d \Delta t` (eq. 12,
    :math:`\dot p^e_e = v^e_d`). Dimension: the number of axes [m]. No
    singularity. Input: the velocity along each commanded axis [m/s].
    """

    type_name: ClassVar[str] = "camera_velocity"
    unit: ClassVar[str] = "m"
    default_gain: ClassVar[float] = 1.0

    def __init__(
        self, params: CameraVelocityParams, robot: RobotModel, name: str = ""
    ) -> None:
        """Resolve the frame; the command starts at rest."""
        super().__init__(params, robot, name)
        self.frame_id = frame_of(robot, params.frame)
        self.axes = list(params.axes)
        self.input_size = len(self.axes)
        self.velocity = np.zeros(len(self.axes))
        self._anchor: tuple[FloatArray, FloatArray, float] | None = None

    @property
    def dim(self) -> int:
        """One row per commanded axis."""
        return len(self.axes)

    def set_input(self, values: FloatArray) -> None:
        """Set the commanded velocity [m/s] along the axes."""
        v = np.asarray(values, dtype=float)
        if v.shape != (len(self.axes),) or not np.all(np.isfinite(v)):
            raise ValueError(f"expected {len(self.axes)} finite velocities, got {v}")
        self.velocity = v.copy()

    def input_values(self) -> tuple[InputValue, ...]:
        """The camera's velocity along each commanded axis [m/s]."""
        return tuple(
            InputValue(
                f"camera velocity {AXIS_MEANING[axis]}",
                "m/s",
                -OPERATOR_SPEED,
                OPERATOR_SPEED,
            )
            for axis in self.axes
        )

    def prepare(self, state: RobotState, dt: float) -> None:
        """Latch the camera's pose and the step's duration."""
        self._anchor = (
            state.frame_position(self.frame_id).copy(),
            state.frame_rotation(self.frame_id)[:, self.axes].T.copy(),
            dt,
        )

    def compute_value(self, state: RobotState) -> FloatArray:
        """Displacement along the latched axes, minus the commanded one."""
        p_a, axes, dt = self.latched(self._anchor)
        return np.asarray(
            axes.dot(state.frame_position(self.frame_id) - p_a) - self.velocity * dt
        )

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """S R_a^T J_t."""
        _, axes, _ = self.latched(self._anchor)
        return np.asarray(axes.dot(state.frame_jacobian(self.frame_id)[:3]))

    def linearize_into(
        self, state: RobotState, value: FloatArray, jacobian: FloatArray
    ) -> None:
        """Value and Jacobian with the anchor read once."""
        p_a, axes, dt = self.latched(self._anchor)
        value[:] = axes.dot(state.frame_position(self.frame_id) - p_a)
        value -= self.velocity * dt
        jacobian[:] = axes.dot(state.frame_jacobian(self.frame_id)[:3])
