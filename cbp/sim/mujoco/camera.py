# SPDX-License-Identifier: Apache-2.0
"""Depth cameras of a MuJoCo scene, by ray cast or OpenGL: PyBullet's frames.

:class:`MujocoDepthCamera` renders a MuJoCo model's geoms by the compiled ray
cast (:mod:`cbp.sim.mujoco.raycast`, ``renderer: raycast``, the default) or
with :class:`mujoco.Renderer` (``renderer: opengl``: depth only, OpenGL
through EGL), and gives the same
:class:`~cbp.perception.frame.DepthFrame` as the PyBullet cameras
(:class:`~cbp.sim.camera.DepthCamera`): the same view and projection
matrices, the same clipping plane, the same depth buffer, the same noise. The
map cannot tell which simulator rendered a frame.

Three things make MuJoCo's OpenGL image PyBullet's (the ray cast samples
PyBullet's rays and gives its buffer as it is):

- **The camera.** MuJoCo's own camera (``mjvGLCamera``, written after the
  scene is updated) is placed at the frame's view, with its frustum at the
  frame's clipping and far planes.
- **The pixels.** OpenGL samples each pixel at its centre; PyBullet's frames
  sample pixel (u, v) at its corner (:mod:`cbp.perception.frame`). The
  frustum is shifted by half a pixel (left and down), so that each pixel's
  centre lies on the ray the frame says it sees.
- **The depth.** MuJoCo gives metric depth along the optical axis (a reversed,
  floating-point depth buffer: precise at any range); it is turned into the
  [0, 1] buffer of the frame's projection, 1 where nothing is seen up to the
  far plane.

The clipping and far planes are MuJoCo's model-wide ``visual/map`` values,
which :class:`mujoco.Renderer` also reads to make depth metric: each capture
sets them for its camera (they change what is drawn, never the physics).
Cameras of one model share one renderer (one OpenGL context) per image size
(:class:`Renderers`). Only geoms are drawn (the groups asked for); sites,
joints and the other decorations are not.
"""

from __future__ import annotations

import mujoco
import numpy as np

from cbp.errors import ConfigError
from cbp.perception.spec import CameraSpec
from cbp.robot import FloatArray, RobotModel
from cbp.sim.camera import SimulatedCamera
from cbp.sim.mujoco.raycast import DEFAULT_GEOM_GROUPS, MujocoRayCaster

__all__ = ["DEFAULT_GEOM_GROUPS", "ROUND_FACETS", "MujocoDepthCamera", "Renderers"]

ROUND_FACETS = 64
"""Facets around a sphere or a cylinder as the renderer draws them: a sphere
of 12 cm radius is then within 0.2 mm of its surface (0.9 mm with MuJoCo's 28,
at the same cost here). Multisampling is off: it blurs colours, not depth,
and costs a fifth of a frame."""

_DECORATIONS = (
    mujoco.mjtVisFlag.mjVIS_TENDON,
    mujoco.mjtVisFlag.mjVIS_RANGEFINDER,
    mujoco.mjtVisFlag.mjVIS_PERTOBJ,
)
"""The drawings MuJoCo makes by default that are no surface a sensor sees."""


class Renderers:
    """One :class:`mujoco.Renderer` (one OpenGL context) per image size, for a model.

    Args:
        model: the MuJoCo model the cameras render.
        geom_groups: the geom groups drawn (others are not seen).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        geom_groups: tuple[int, ...] = DEFAULT_GEOM_GROUPS,
    ) -> None:
        """No context is made until a camera first renders."""
        self.model = model
        self._by_size: dict[tuple[int, int], mujoco.Renderer] = {}
        option = mujoco.MjvOption()
        option.geomgroup[:] = [
            int(g in geom_groups) for g in range(len(option.geomgroup))
        ]
        for groups in (option.sitegroup, option.tendongroup, option.flexgroup):
            groups[:] = 0
        # Decorations off; static bodies (the world's geoms) and skins stay.
        for flag in _DECORATIONS:
            option.flags[flag] = 0
        #: What the cameras draw: the chosen geom groups, nothing else.
        self.option = option

    def get(self, width: int, height: int) -> mujoco.Renderer:
        """The renderer of images of ``width`` x ``height`` [px], made once.

        The model's offscreen buffer grows to the size if it is smaller; its
        spheres and cylinders are drawn with at least
        :data:`ROUND_FACETS` facets around, without multisampling.
        """
        key = (width, height)
        if key not in self._by_size:
            visual = self.model.vis.global_
            visual.offwidth = max(visual.offwidth, width)
            visual.offheight = max(visual.offheight, height)
            quality = self.model.vis.quality
            quality.numslices = max(quality.numslices, ROUND_FACETS)
            quality.numstacks = max(quality.numstacks, ROUND_FACETS)
            quality.offsamples = 0
            renderer = mujoco.Renderer(self.model, height, width)
            renderer.enable_depth_rendering()
            self._by_size[key] = renderer
        return self._by_size[key]

    @property
    def count(self) -> int:
        """How many renderers (OpenGL contexts) there are."""
        return len(self._by_size)

    def close(self) -> None:
        """Free every renderer's OpenGL context."""
        for renderer in self._by_size.values():
            renderer.close()
        self._by_size.clear()


class MujocoDepthCamera(SimulatedCamera):
    """A camera rendering depth images of a MuJoCo scene: fixed or mounted.

    The spec's ``renderer`` chooses how: ``raycast`` (the default), the
    compiled ray cast of the model's geoms
    (:class:`~cbp.sim.mujoco.raycast.MujocoRayCaster`), or ``opengl``, MuJoCo's
    renderer (this module); ``tiny`` is PyBullet's. A mounted camera follows
    the robot state passed to :meth:`capture` (the robot's kinematics, as
    PyBullet's cameras do); the scene is drawn as ``data`` holds it (its
    placements brought up to its positions first).

    Args:
        model: the MuJoCo model.
        data: its data (the state drawn).
        spec: pose (or parent frame and offset), resolution, field of view,
            clipping planes and renderer.
        robot: the robot a mounted camera's ``parent`` frame belongs to.
        renderers: the OpenGL renderers shared by the model's cameras
            (``opengl``). Default: the camera's own.
        caster: the ray caster shared by the model's cameras (``raycast``).
            Default: the camera's own.

    Raises:
        ConfigError: a mounted camera without a robot, or with an unknown
            frame; a renderer MuJoCo does not have.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        spec: CameraSpec,
        robot: RobotModel | None = None,
        renderers: Renderers | None = None,
        caster: MujocoRayCaster | None = None,
    ) -> None:
        """Compute the projection (and a fixed camera's view) once."""
        super().__init__(spec, robot)
        if spec.renderer not in ("raycast", "opengl"):
            raise ConfigError(
                f"camera '{spec.name}': renderer '{spec.renderer}' is PyBullet's; "
                "on MuJoCo choose 'raycast' or 'opengl'",
                "renderer",
            )
        self.model = model
        self.data = data
        self._caster: MujocoRayCaster | None = None
        self._renderers: Renderers | None = None
        if spec.renderer == "raycast":
            self._caster = caster or MujocoRayCaster(model, data)
        else:
            self._renderers = renderers or Renderers(model)
        # The frustum's half extents at the clipping plane, and the half-pixel
        # shift that puts OpenGL's pixel centres on the frame's rays.
        near = self._clip_near
        half_width = near / self.projection[0, 0]
        half_height = near / self.projection[1, 1]
        self._frustum = (
            -half_width / spec.width,  # centre
            half_width,
            -half_height - half_height / spec.height,  # bottom
            half_height - half_height / spec.height,  # top
        )
        self._gl_camera = mujoco.MjvCamera()
        self._gl_camera.type = mujoco.mjtCamera.mjCAMERA_FREE

    def close(self) -> None:
        """Free the OpenGL renderers (shared: the model's other cameras' too)."""
        if self._renderers is not None:
            self._renderers.close()

    def _render(self) -> FloatArray:
        """The depth buffer through :attr:`view`: ray cast, or MuJoCo's renderer."""
        s = self.spec
        if self._caster is not None:
            return self._caster.render(
                self.view, self.projection, s.width, s.height, self._clip_near, s.far
            )
        return self._render_opengl()

    def _render_opengl(self) -> FloatArray:
        """MuJoCo's depth through :attr:`view`, as the frame's depth buffer."""
        assert self._renderers is not None
        s, m = self.spec, self.model
        near, far = self._clip_near, s.far
        extent = m.stat.extent
        m.vis.map.znear = near / extent
        m.vis.map.zfar = far / extent
        renderer = self._renderers.get(s.width, s.height)
        mujoco.mj_kinematics(m, self.data)
        renderer.update_scene(self.data, self._gl_camera, self._renderers.option)
        R, t = self.view[:3, :3], self.view[:3, 3]
        centre, half_width, bottom, top = self._frustum
        for camera in renderer.scene.camera:  # both eyes: MuJoCo draws their mean
            camera.pos[:] = -R.T.dot(t)
            camera.forward[:] = -R[2]
            camera.up[:] = R[1]
            camera.frustum_center = centre
            camera.frustum_width = half_width
            camera.frustum_bottom = bottom
            camera.frustum_top = top
            camera.frustum_near = near
            camera.frustum_far = far
            camera.orthographic = 0
        depth = renderer.render().astype(float)
        with np.errstate(divide="ignore"):
            buffer = far / (far - near) * (1.0 - near / depth)
        buffer[depth >= far * (1.0 - 1e-6)] = 1.0
        return np.asarray(buffer)
