# SPDX-License-Identifier: Apache-2.0
"""Task ``goal_pose``: move a frame toward a goal pose (CAT paper, eq. 1)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Literal

import numba
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from cbp.errors import ConfigError, TargetNotSetError, located
from cbp.plugin import FloatArray, PluginParams, Task
from cbp.robot import RobotModel
from cbp.spatial import Pose, checked_pose, checked_pose_into, pose_error_into
from cbp.state import RobotState

#: The dtype of the goals checked in one compiled call (numpy's built-in
#: dtypes are singletons; any other goes the long way).
_FLOAT = np.dtype(np.float64)


@dataclass(frozen=True, kw_only=True)
class GoalPoseParams(PluginParams):
    """Parameters of :class:`GoalPoseTask`."""

    frame: str | None = None
    """Frame to move (a link or a frame of the URDF); default: the robot's end
    effector (``end_effector`` in robot.yaml)."""
    max_step_translation: float = 0.01
    """Largest translation asked for in one step [m]."""
    max_step_rotation: float = 0.05
    """Largest rotation asked for in one step [rad]."""
    clip: Literal["uniform", "independent"] = "uniform"
    """``uniform``: scale translation and rotation by one factor, so both reach
    the goal together (straight-line motion in pose space); ``independent``:
    clip each on its own (a small rotation then completes in one step and the
    joint-space direction turns sharply whenever the goal rotates)."""
    target: Pose | None = None
    """Initial goal; usually set every period by the goal stream."""

    def __post_init__(self) -> None:
        """Step limits must be positive."""
        for name in ("max_step_translation", "max_step_rotation"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"must be > 0, got {getattr(self, name)}", name)


class GoalPoseTask(Task[GoalPoseParams]):
    r"""Pose error of a frame with respect to a goal pose, in the world frame.

    .. math::

        f(q) = \begin{bmatrix} p(q) - p_g \\ \log_3(R(q) R_g^T) \end{bmatrix}

    Dimension 6: translation error [m], then rotation error [rad] as a rotation
    vector, both in world coordinates. Jacobian: the frame's LOCAL_WORLD_ALIGNED
    Jacobian, with the rotation rows mapped through :math:`J_{\log_3}(M) M^T`,
    :math:`M = R R_g^T`. The rotation rows are singular when the rotation error
    reaches π.

    The engine asks for a change of :math:`-k f` per step; this task scales it
    down so that its translation and rotation parts stay within
    ``max_step_translation`` and ``max_step_rotation`` (by one common factor, or
    each on its own with ``clip: independent``), so a far goal is approached in
    bounded steps (CAT's small steps, each checked for collisions).
    """

    type_name: ClassVar[str] = "goal_pose"
    unit: ClassVar[str] = "m|rad"

    def __init__(
        self, params: GoalPoseParams, robot: RobotModel, name: str = ""
    ) -> None:
        """Resolve the frame; take the initial target when one is given."""
        super().__init__(params, robot, name)
        self.frame = params.frame or robot.end_effector
        self.frame_id = located(robot.frame_id, self.frame, "frame")
        self._target: pin.SE3 | None = None
        self._has_target = False
        # The goal, written in place by set_target (read by the pose error).
        self._goal_translation = np.zeros(3)
        self._goal_rotation_t = np.eye(3)
        # Compile the pose error (or load it from numba's cache) now, on arrays
        # of the kinds a step passes, rather than in the first control step.
        state = RobotState(robot)
        self._views = (
            state,
            state.frame_rotation(self.frame_id),
            state.frame_position(self.frame_id),
        )
        pose_error_into(
            state.frame_rotation(self.frame_id),
            state.frame_position(self.frame_id),
            np.eye(3),
            np.zeros(3),
            state.frame_jacobian(self.frame_id),
            np.empty(6),
            np.empty((6, robot.nv)),
        )
        _limit_step(np.zeros(6), 1.0, 1.0, True)
        if params.target is not None:
            target = params.target.to_se3()
            self._set(np.array(target.translation), np.array(target.rotation))

    @property
    def dim(self) -> int:
        """Six rows: translation then rotation."""
        return 6

    def set_target(self, position: npt.ArrayLike, rotation: npt.ArrayLike) -> None:
        """Set the goal: position (3,) [m] and rotation matrix (3, 3), world frame.

        Raises:
            InvalidTargetError: wrong shape, NaN or not a rotation; the goal is kept.
        """
        if (
            type(position) is np.ndarray
            and type(rotation) is np.ndarray
            and position.dtype is _FLOAT
            and rotation.dtype is _FLOAT
            and position.ndim == 1
            and rotation.ndim == 2
            and checked_pose_into(
                position, rotation, self._goal_translation, self._goal_rotation_t
            )
        ):  # arrays of floats, checked and copied in one compiled call
            self._target = None
            self._has_target = True
            return
        self._set(*checked_pose(position, rotation, f"{self.name} target"))

    def _set(self, position: FloatArray, rotation: FloatArray) -> None:
        # As numpy arrays, not read through pinocchio every step; the SE3 of
        # ``target`` is made when asked for.
        self._goal_translation[:] = position
        self._goal_rotation_t[:] = rotation.T
        self._target = None
        self._has_target = True

    @property
    def target(self) -> pin.SE3:
        """The current goal pose."""
        if self._target is None:
            if not self._has_target:
                raise TargetNotSetError(
                    f"{self.name} ({self.type_name}): no target set"
                )
            self._target = pin.SE3(self._goal_rotation_t.T, self._goal_translation)
        return self._target

    @property
    def goal_frame(self) -> str:
        """The frame moved to the goal (``params.frame`` or the end effector)."""
        return self.frame

    def compute_value(self, state: RobotState) -> FloatArray:
        """Translation error then rotation vector, world frame."""
        return self.linearize(state).value

    def compute_jacobian(self, state: RobotState) -> FloatArray:
        """World-aligned frame Jacobian with the log map's Jacobian on rotation rows."""
        return self.linearize(state).jacobian

    def linearize_into(
        self, state: RobotState, value: FloatArray, jacobian: FloatArray
    ) -> None:
        """Value and Jacobian written in place, sharing the rotation error matrix."""
        if not self._has_target:
            raise TargetNotSetError(f"{self.name} ({self.type_name}): no target set")
        frame = self.frame_id
        views = self._views
        if views[0] is not state:
            # The frame's rotation and position in ``state`` (views that its
            # updates rewrite in place), asked for once per state.
            views = self._views = (
                state,
                state.frame_rotation(frame),
                state.frame_position(frame),
            )
        pose_error_into(
            views[1],
            views[2],
            self._goal_rotation_t,
            self._goal_translation,
            state.frame_jacobian(frame),
            value,
            jacobian,
        )

    def limit_step(self, desired: FloatArray) -> FloatArray:
        """Bound the translation and rotation asked for in one step."""
        limited = np.array(desired, dtype=float)
        self.limit_step_into(limited)
        return limited

    def limit_step_into(self, desired: FloatArray) -> None:
        """:meth:`limit_step` in place, in one compiled call."""
        params = self.params
        _limit_step(
            desired,
            params.max_step_translation,
            params.max_step_rotation,
            params.clip == "uniform",
        )

    def __repr__(self) -> str:
        """Type, name, frame and step limits."""
        p = self.params
        return (
            f"GoalPoseTask(name={self.name!r}, frame={p.frame!r}, "
            f"max_step_translation={p.max_step_translation}, "
            f"max_step_rotation={p.max_step_rotation})"
        )


@numba.njit(cache=True, nogil=True)
def _limit_step(
    desired: FloatArray, max_translation: float, max_rotation: float, uniform: bool
) -> None:
    """Scale the translation and rotation of ``desired`` (6,) to their limits.

    By one factor (``uniform``) or each by its own.
    """
    x, y, z = desired[0], desired[1], desired[2]
    rx, ry, rz = desired[3], desired[4], desired[5]
    translation = math.sqrt(x * x + y * y + z * z)
    rotation = math.sqrt(rx * rx + ry * ry + rz * rz)
    st = sr = 1.0
    if translation > max_translation:
        st = max_translation / translation
    if uniform:
        if rotation * st > max_rotation:
            st = max_rotation / rotation
        sr = st
    elif rotation > max_rotation:
        sr = max_rotation / rotation
    if st != 1.0:
        for i in range(3):
            desired[i] *= st
    if sr != 1.0:
        for i in range(3, 6):
            desired[i] *= sr
