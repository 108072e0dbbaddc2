# SPDX-License-Identifier: Apache-2.0
"""A simulated depth camera in PyBullet, and depth images back to world points.

PyBullet's ER_TINY_RENDERER samples pixel (u, v) at NDC x = 2u/W - 1,
y = 2(H - 1 - v)/H - 1 (not at pixel centres), and returns its matrices
column-major. With that convention the unprojection through inv(P V) matches
analytic surfaces to well under a millimetre; with pixel centres it is biased by
2-4 mm (measured, ``../shared/notes/perception.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as pb

from cbp.perception.spec import CameraSpec
from cbp.robot import FloatArray

__all__ = ["DepthCamera", "DepthFrame"]


@dataclass(frozen=True)
class DepthFrame:
    """One depth image with what is needed to turn it into points.

    Attributes:
        depth: PyBullet's depth buffer in [0, 1], (H, W).
        view: the 4x4 view matrix (world to camera, OpenGL convention).
        projection: the 4x4 projection matrix.
        near: near plane [m].
        far: far plane [m].
    """

    depth: FloatArray
    view: FloatArray
    projection: FloatArray
    near: float
    far: float

    @property
    def position(self) -> FloatArray:
        """The optical centre in the world [m]."""
        R, t = self.view[:3, :3], self.view[:3, 3]
        return np.asarray(-R.T.dot(t))

    def ranges(self) -> FloatArray:
        """Metric depth along the optical axis per pixel [m]; inf on background."""
        z = self.depth
        n, f = self.near, self.far
        metric = f * n / (f - (f - n) * z)
        return np.where(z >= 1.0 - 1e-6, np.inf, metric)

    def points(self) -> tuple[FloatArray, np.ndarray]:
        """World points (H, W, 3) of every pixel, and the mask of real hits (H, W)."""
        h, w = self.depth.shape
        u = np.arange(w)
        v = np.arange(h)
        x = 2.0 * u / w - 1.0
        y = 2.0 * (h - 1 - v) / h - 1.0
        X, Y = np.meshgrid(x, y)
        Z = 2.0 * self.depth - 1.0
        ndc = np.stack([X, Y, Z, np.ones_like(Z)], axis=-1).reshape(-1, 4)
        inv = np.linalg.inv(self.projection.dot(self.view))
        world = ndc.dot(inv.T)
        world = world[:, :3] / world[:, 3:4]
        hit = self.depth < 1.0 - 1e-6
        return world.reshape(h, w, 3), hit

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


class DepthCamera:
    """A fixed camera rendering depth images of a PyBullet client.

    Args:
        client: PyBullet client id.
        spec: pose, resolution, field of view and clipping planes.
    """

    def __init__(self, client: int, spec: CameraSpec) -> None:
        """Compute the view and projection matrices once."""
        self.client = client
        self.spec = spec
        self._view_list = pb.computeViewMatrix(
            list(spec.position), list(spec.target), list(spec.up)
        )
        self._projection_list = pb.computeProjectionMatrixFOV(
            spec.fov_deg, spec.width / spec.height, spec.near, spec.far
        )
        # PyBullet's matrices are column-major.
        self.view = np.array(self._view_list).reshape(4, 4).T
        self.projection = np.array(self._projection_list).reshape(4, 4).T

    def capture(self) -> DepthFrame:
        """Render one depth image (tiny renderer; no window needed)."""
        s = self.spec
        _, _, _, depth, _ = pb.getCameraImage(
            s.width,
            s.height,
            viewMatrix=self._view_list,
            projectionMatrix=self._projection_list,
            renderer=pb.ER_TINY_RENDERER,
            flags=pb.ER_NO_SEGMENTATION_MASK,
            physicsClientId=self.client,
        )
        buffer = np.asarray(depth, dtype=float).reshape(s.height, s.width)
        return DepthFrame(buffer, self.view, self.projection, s.near, s.far)
