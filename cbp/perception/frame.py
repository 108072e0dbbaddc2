# SPDX-License-Identifier: Apache-2.0
"""Depth frames: one depth image and what turns it into points, whatever rendered it.

PyBullet's ER_TINY_RENDERER samples pixel (u, v) at NDC x = 2u/W - 1,
y = 2(H - 1 - v)/H - 1 (not at pixel centres), and returns its matrices
column-major. With that convention the unprojection through inv(P V) matches
analytic surfaces to well under a millimetre; with pixel centres it is biased by
2-4 mm (measured, ``../shared/notes/perception.md``).

A camera's ``near`` is its sensor's minimum range, not the renderer's clipping
plane. A renderer clips what lies nearer than its near plane and shows what is
behind it, so a board 4 cm in front of a wrist camera with a 5 cm near plane
would be seen *through*, and the map would free the board's cells. A real depth
sensor gives no reading there instead. Frames are therefore rendered with a
clipping plane at :data:`RENDER_NEAR_FRACTION` of the far plane (at most the
minimum range), and pixels nearer than the minimum range hold no reading.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from cbp.robot import FloatArray, RobotModel

__all__ = [
    "RENDER_NEAR_FRACTION",
    "DepthFrame",
    "camera_parent",
    "look_at",
    "perspective",
]

RENDER_NEAR_FRACTION = 1e-3
"""The rendering clip plane as a fraction of the far plane: 2.5 mm for a 2.5 m
camera, where PyBullet's depth is within 0.2 mm at 2.4 m (0.02 mm with 1 cm)."""

_FAR_PLANE = 1.0 - 1e-6
"""Depth buffer values from here up are the far plane: nothing seen."""
_FAR_BUFFER = 1.0 + 1e-6
"""The largest depth buffer value that is a reading: the far plane comes back
as 1.0000001 (float32 rounding) with a near plane of a few millimetres."""


@dataclass(frozen=True)
class DepthFrame:
    """One depth image with what is needed to turn it into points.

    Attributes:
        depth: PyBullet's depth buffer in [0, 1], (H, W).
        view: the 4x4 view matrix (world to camera, OpenGL convention).
        projection: the 4x4 projection matrix.
        near: the projection's near (clipping) plane [m].
        far: far plane [m].
        camera: the camera's name.
        min_range: the sensor's minimum range [m]: nearer pixels hold no
            reading (what a real sensor gives, rather than a view past them).
    """

    depth: FloatArray
    view: FloatArray
    projection: FloatArray
    near: float
    far: float
    camera: str = ""
    min_range: float = 0.0

    @property
    def closest(self) -> float:
        """The nearest depth a reading can have [m]."""
        return max(self.near, self.min_range)

    @property
    def position(self) -> FloatArray:
        """The optical centre in the world [m]."""
        R, t = self.view[:3, :3], self.view[:3, 3]
        return np.asarray(-R.T.dot(t))

    def valid(self) -> np.ndarray:
        """Pixels that hold a reading (H, W).

        Finite, within [0, 1], and not nearer than the minimum range.
        """
        z = self.depth
        with np.errstate(invalid="ignore"):
            nearest = self._buffer_at(self.min_range)
            return np.isfinite(z) & (z >= nearest) & (z <= _FAR_BUFFER)

    @property
    def buffer_limits(self) -> tuple[float, float, float]:
        """Depth buffer values: the minimum range, the far plane, the largest valid.

        A pixel holds a reading when its value is finite and between the first
        and the last; from the second up it sees nothing up to the far plane.
        """
        return self._buffer_at(self.min_range), _FAR_PLANE, _FAR_BUFFER

    @functools.cached_property
    def unprojection(self) -> FloatArray:
        """From normalised device coordinates to the world: inv(projection view).

        Computed once per frame (the map's passes and :meth:`points` use it).
        """
        return np.asarray(np.linalg.inv(self.projection.dot(self.view)))

    def _buffer_at(self, distance: float) -> float:
        """The depth buffer's value at ``distance`` along the axis (0 at near)."""
        n, f = self.near, self.far
        if distance <= n:
            return 0.0
        return f / (f - n) * (1.0 - n / distance)

    def problem(self, min_valid_fraction: float) -> str | None:
        """Why the frame should not be used, or None.

        A reading is a finite depth in (0, 1]: 1 is the far plane (nothing seen
        up to it, which the map uses), 0 the near plane exactly, what a failed
        render or a blinded sensor gives. A pixel nearer than the minimum range
        counts here (the camera works; something is close in front of it),
        though the map takes nothing from it. A frame with fewer than
        ``min_valid_fraction`` of its pixels reading, or of the wrong shape, is
        refused.
        """
        z = self.depth
        if z.ndim != 2 or z.size == 0:
            return f"depth image of shape {z.shape}"
        if not np.all(np.isfinite(self.view)):
            return "camera pose not finite"
        with np.errstate(invalid="ignore"):
            reading = np.isfinite(z) & (z > 0.0) & (z <= _FAR_BUFFER)
        fraction = float(np.count_nonzero(reading)) / z.size
        if fraction < min_valid_fraction:
            return (
                f"{fraction:.0%} of its pixels hold a reading "
                f"(perception.min_valid_fraction: {min_valid_fraction:.0%})"
            )
        return None

    def ranges(self) -> FloatArray:
        """Metric depth along the optical axis per pixel [m].

        inf on background (nothing before the far plane), NaN where the pixel
        holds no valid reading.
        """
        z = self.depth
        n, f = self.near, self.far
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            metric = f * n / (f - (f - n) * z)
            out = np.where(z >= _FAR_PLANE, np.inf, metric)
        out[~self.valid()] = np.nan
        return np.asarray(out)

    def points(self, stride: int = 1) -> tuple[FloatArray, np.ndarray]:
        """World points (H, W, 3) of every pixel, and the mask of real hits (H, W).

        ``stride``: every so many pixels both ways only (then (H / stride, W /
        stride, 3) and (H / stride, W / stride), rounded up).
        """
        h, w = self.depth.shape
        u = np.arange(0, w, stride)
        v = np.arange(0, h, stride)
        x = 2.0 * u / w - 1.0
        y = 2.0 * (h - 1 - v) / h - 1.0
        X, Y = np.meshgrid(x, y)
        depth = self.depth[::stride, ::stride]
        Z = 2.0 * depth - 1.0
        ndc = np.stack([X, Y, Z, np.ones_like(Z)], axis=-1).reshape(-1, 4)
        world = ndc.dot(self.unprojection.T)
        world = world[:, :3] / world[:, 3:4]
        with np.errstate(invalid="ignore"):
            hit = self.valid()[::stride, ::stride] & (depth < _FAR_PLANE)
        return world.reshape(len(v), len(u), 3), hit

    def project(self, points: FloatArray) -> tuple[np.ndarray, np.ndarray, FloatArray]:
        """Pixel (row, column) of world points (n, 3) and their depth along the axis.

        Returns (rows, cols, depth); pixels outside the image are -1.
        """
        h, w = self.depth.shape
        homog = np.hstack([points, np.ones((len(points), 1))])
        cam = homog.dot(self.view.T)
        clip = cam.dot(self.projection.T)
        depth = -cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            ndc = clip[:, :2] / clip[:, 3:4]
        cols = np.rint((ndc[:, 0] + 1.0) * w / 2.0).astype(np.intp)
        rows = np.rint(h - 1 - (ndc[:, 1] + 1.0) * h / 2.0).astype(np.intp)
        inside = (depth > 0) & (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
        rows[~inside] = -1
        cols[~inside] = -1
        return rows, cols, depth


def camera_parent(parent: str, robot: RobotModel) -> str:
    """The frame a camera named ``parent`` is mounted on.

    ``end_effector`` names the robot's end effector, so a configuration fits
    any arm.
    """
    return robot.end_effector if parent == "end_effector" else parent


def perspective(fov_deg: float, aspect: float, near: float, far: float) -> FloatArray:
    """The OpenGL projection matrix of a vertical field of view (4, 4)."""
    f = 1.0 / np.tan(np.deg2rad(fov_deg) / 2.0)
    return np.array(
        [
            [f / aspect, 0.0, 0.0, 0.0],
            [0.0, f, 0.0, 0.0],
            [0.0, 0.0, (far + near) / (near - far), 2.0 * far * near / (near - far)],
            [0.0, 0.0, -1.0, 0.0],
        ]
    )


def look_at(eye: npt.ArrayLike, target: npt.ArrayLike, up: npt.ArrayLike) -> FloatArray:
    """The OpenGL view matrix (world to camera) of a camera at ``eye`` (4, 4)."""
    eye, target, up = (np.asarray(v, dtype=float) for v in (eye, target, up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    side = np.cross(forward, up)
    side /= np.linalg.norm(side)
    true_up = np.cross(side, forward)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = side, true_up, -forward
    view[:3, 3] = -view[:3, :3] @ eye
    return view
