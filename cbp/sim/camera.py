# SPDX-License-Identifier: Apache-2.0
"""Simulated depth cameras, fixed or on a robot link: ray cast or tiny renderer.

A PyBullet camera renders with a compiled ray cast against the scene's shapes
(:class:`~cbp.sim.raycast.RayCaster`, ``renderer: raycast``, the default) or
with PyBullet's tiny renderer (``renderer: tiny``); their pixels agree within
1 mm of depth but on silhouette edges. Each capture is a
:class:`~cbp.perception.frame.DepthFrame`, the same record a real sensor's
driver would give the map (:mod:`cbp.perception`), which does not know what
rendered it. The pixel convention and the clipping plane are
described in :mod:`cbp.perception.frame`.

:class:`SimulatedCamera` is what every simulator's cameras share (the
matrices, the mount, the noise); MuJoCo's render by the same ray cast of its
geoms or with its OpenGL renderer (:mod:`cbp.sim.mujoco.camera`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError, FrameNotFoundError
from cbp.perception.frame import RENDER_NEAR_FRACTION, DepthFrame, camera_parent
from cbp.perception.spec import CameraSpec
from cbp.robot import FloatArray, RobotModel
from cbp.sim.bullet import pb
from cbp.sim.depth_noise import NoisyDepth
from cbp.sim.raycast import RayCaster
from cbp.state import RobotState

__all__ = ["DepthCamera", "SimulatedCamera"]


class SimulatedCamera:
    """A simulated depth camera, fixed or mounted, whatever renders its images.

    It keeps the camera's matrices (PyBullet's, so that every simulator's
    frames carry the same ones), follows the robot frame it is mounted on, and
    turns each rendered depth buffer into a
    :class:`~cbp.perception.frame.DepthFrame` with the camera's noise. A
    subclass renders (:meth:`_render`).

    Args:
        spec: pose (or parent frame and offset), resolution, field of view and
            clipping planes.
        robot: the robot a mounted camera's ``parent`` frame belongs to.

    Raises:
        ConfigError: a mounted camera without a robot, or with an unknown frame.
    """

    def __init__(self, spec: CameraSpec, robot: RobotModel | None = None) -> None:
        """Compute the projection (and a fixed camera's view) once."""
        self.spec = spec
        self.name = spec.name
        self._clip_near = min(spec.near, RENDER_NEAR_FRACTION * spec.far)
        self._projection_list = pb.computeProjectionMatrixFOV(
            spec.fov_deg, spec.width / spec.height, self._clip_near, spec.far
        )
        # PyBullet's matrices are column-major.
        self.projection = np.array(self._projection_list).reshape(4, 4).T
        self._noise = NoisyDepth(spec.noise, spec.name) if spec.noise.enabled else None
        self._frame: int | None = None
        self._offset = spec.offset.to_se3()
        if spec.parent is not None:
            if robot is None:
                raise ConfigError(
                    f"camera '{spec.name}' is mounted on '{spec.parent}' but there "
                    "is no robot",
                    "parent",
                )
            try:
                self._frame = robot.frame_id(camera_parent(spec.parent, robot))
            except FrameNotFoundError as exc:
                raise ConfigError(str(exc), "parent") from None
            self._view_list: list[float] = []
            self.view = np.eye(4)
        else:
            assert spec.position is not None
            assert spec.target is not None
            self._set_view(spec.position, spec.target, spec.up)

    @property
    def mounted(self) -> bool:
        """Whether the camera moves with the robot."""
        return self._frame is not None

    def optical_pose(self, state: RobotState | None = None) -> pin.SE3:
        """The optical frame in the world (+z along the axis, +y down the image).

        A mounted camera's pose is taken from ``state`` (the robot when the
        frame is taken).
        """
        if self._frame is None:
            R = self.view[:3, :3].T.dot(np.diag([1.0, -1.0, -1.0]))
            return pin.SE3(R, -self.view[:3, :3].T.dot(self.view[:3, 3]))
        if state is None:
            raise ValueError(f"camera '{self.name}' is mounted: pass the robot state")
        return state.data.oMf[self._frame] * self._offset

    def capture(self, state: RobotState | None = None) -> DepthFrame:
        """Render one depth image (no window needed).

        With the camera's noise model on (``noise:``, the default) the image
        is what the sensor would give (:mod:`cbp.sim.depth_noise`).

        Args:
            state: the robot at capture time (mounted cameras; kinematics
                updated).
        """
        if self._frame is not None:
            M = self.optical_pose(state)
            eye = M.translation
            self._set_view(eye, eye + M.rotation[:, 2], -M.rotation[:, 1])
        s = self.spec
        buffer = self._render()
        frame = DepthFrame(
            buffer,
            self.view.copy(),
            self.projection,
            self._clip_near,
            s.far,
            self.name,
            min_range=s.near,
        )
        if self._noise is None:
            return frame
        far_plane = frame.buffer_limits[1]
        noisy = self._noise.apply(buffer, self._clip_near, s.far, far_plane)
        return dataclasses.replace(frame, depth=noisy)

    def close(self) -> None:
        """Release what the camera renders with (nothing here)."""

    def _render(self) -> FloatArray:
        """The depth buffer (height, width) through :attr:`view` now.

        In [0, 1] as PyBullet gives it (:mod:`cbp.perception.frame`): 0 at the
        clipping plane, 1 where nothing is seen up to the far plane.
        """
        raise NotImplementedError(f"{type(self).__name__} renders nothing")

    def _set_view(self, eye: object, target: object, up: object) -> None:
        self._view_list = pb.computeViewMatrix(
            [float(v) for v in eye],  # type: ignore[attr-defined]
            [float(v) for v in target],  # type: ignore[attr-defined]
            [float(v) for v in up],  # type: ignore[attr-defined]
        )
        self.view = np.array(self._view_list).reshape(4, 4).T


class DepthCamera(SimulatedCamera):
    """A camera rendering depth images of a PyBullet client: fixed or mounted.

    Args:
        client: PyBullet client id.
        spec: pose (or parent frame and offset), resolution, field of view and
            clipping planes.
        robot: the robot a mounted camera's ``parent`` frame belongs to.
        caster: the ray caster of ``client`` to render with (``renderer:
            raycast``); cameras of one client may share one. Default: a
            camera's own.

    Raises:
        ConfigError: a mounted camera without a robot, or with an unknown
            frame; MuJoCo's renderer (``opengl``).
    """

    def __init__(
        self,
        client: int,
        spec: CameraSpec,
        robot: RobotModel | None = None,
        caster: RayCaster | None = None,
    ) -> None:
        """Compute the projection (and a fixed camera's view) once."""
        super().__init__(spec, robot)
        if spec.renderer == "opengl":
            raise ConfigError(
                f"camera '{spec.name}': renderer 'opengl' is MuJoCo's; on PyBullet "
                "choose 'raycast' or 'tiny'",
                "renderer",
            )
        self.client = client
        self._caster = (
            (caster or RayCaster(client)) if spec.renderer == "raycast" else None
        )

    def _render(self) -> FloatArray:
        """The ray caster's depth buffer, or PyBullet's tiny renderer's."""
        s = self.spec
        if self._caster is not None:
            return self._caster.render(
                self.view, self.projection, s.width, s.height, self._clip_near, s.far
            )
        _, _, _, depth, _ = pb.getCameraImage(
            s.width,
            s.height,
            viewMatrix=self._view_list,
            projectionMatrix=self._projection_list,
            renderer=pb.ER_TINY_RENDERER,
            flags=pb.ER_NO_SEGMENTATION_MASK,
            physicsClientId=self.client,
        )
        return np.asarray(depth, dtype=float).reshape(s.height, s.width)
