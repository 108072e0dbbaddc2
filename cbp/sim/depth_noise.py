# SPDX-License-Identifier: Apache-2.0
"""Depth noise and dropout of simulated cameras: what a rendered frame lacks.

A renderer's depth is exact; a depth sensor's is not. :class:`NoisyDepth`
applies a camera's :class:`~cbp.perception.spec.DepthNoise` to each depth
buffer it renders, in three steps on the metric depth along the optical axis:

1. **Edges.** A pixel whose depth lies more than ``edge_jump`` beyond one of
   its four neighbours' gives no reading (the far side of a depth edge, and
   the background beside an object's outline).
2. **Axial noise.** Every other reading moves along its ray by a normal
   deviate of standard deviation sigma(z) = sigma_0 + sigma_growth (z - z0)^2.
   A reading pushed past the far plane gives none (out of range);
   background (nothing up to the far plane) stays background.
3. **Dropout.** A ``dropout`` fraction of the pixels, at random, give no
   reading.

The result is a depth buffer again (the convention of
:class:`~cbp.perception.frame.DepthFrame`), NaN where there is no reading. Each
camera draws from its own random stream, seeded by the model's ``seed`` and the
camera's name, so a run whose frames are captured in a fixed order (the
virtual clock) gets the same frames every time.
"""

from __future__ import annotations

import zlib

import numba
import numpy as np

from cbp.perception.spec import DepthNoise
from cbp.robot import FloatArray

__all__ = ["NoisyDepth"]


class NoisyDepth:
    """One camera's noise: its model and its random stream.

    Args:
        noise: the model.
        camera: the camera's name (with ``noise.seed``, it seeds the stream).
    """

    def __init__(self, noise: DepthNoise, camera: str) -> None:
        """Seed the camera's stream."""
        self.noise = noise
        self._rng = np.random.default_rng([noise.seed, zlib.crc32(camera.encode())])

    def apply(
        self, buffer: FloatArray, near: float, far: float, far_plane: float
    ) -> FloatArray:
        """The depth buffer (H, W) as the sensor would give it (a new array).

        Args:
            buffer: the rendered depth buffer, in [0, 1].
            near: the projection's near plane [m].
            far: its far plane [m].
            far_plane: buffer values from here up see nothing up to the far
                plane (:attr:`DepthFrame.buffer_limits`).
        """
        noise = self.noise
        z = np.ascontiguousarray(buffer, dtype=float)
        hit = z < far_plane  # a reading nearer than the far plane (NaN: False)
        deviates = self._rng.standard_normal(
            int(np.count_nonzero(hit)), dtype=np.float32
        )
        out = _noisy(
            z,
            far_plane,
            near,
            far,
            noise.sigma_0,
            noise.sigma_growth,
            noise.z0,
            noise.edge_jump,
            deviates,
        )
        if noise.dropout > 0.0:
            count = self._rng.binomial(z.size, noise.dropout)
            out.reshape(-1)[self._rng.choice(z.size, count, replace=False)] = np.nan
        return np.asarray(out)


@numba.njit(cache=True, nogil=True)
def _noisy(
    z: FloatArray,
    far_plane: float,
    near: float,
    far: float,
    sigma_0: float,
    sigma_growth: float,
    z0: float,
    edge_jump: float,
    deviates: np.ndarray,
) -> FloatArray:
    """Steps 1 and 2 of :class:`NoisyDepth` in one pass: a new buffer.

    ``deviates``: one normal deviate per pixel nearer than ``far_plane``, in
    row order (as numpy would draw them for those pixels, so the same stream
    gives the same frames as the array expressions this pass replaced).
    """
    h, w = z.shape
    out = z.copy()
    depth = np.full((h, w), np.inf)
    n = 0
    scale = far / (far - near)
    for r in range(h):
        for c in range(w):
            v = z[r, c]
            if not v < far_plane:
                continue
            d = far * near / (far - (far - near) * v)
            depth[r, c] = d
            d += (sigma_0 + sigma_growth * (d - z0) ** 2) * np.float64(deviates[n])
            n += 1
            if d >= far or d <= 0.0:
                out[r, c] = np.nan  # out of range
            else:
                out[r, c] = scale * (1.0 - near / d)
    if edge_jump > 0.0:
        # A pixel more than edge_jump beyond a neighbour gives no reading
        # (background beside an object lies inf beyond it; NaN compares false).
        for r in range(h):
            for c in range(w):
                here = depth[r, c]
                for rr, cc in ((r, c - 1), (r, c + 1), (r - 1, c), (r + 1, c)):
                    if 0 <= rr < h and 0 <= cc < w and here - depth[rr, cc] > edge_jump:
                        out[r, c] = np.nan
                        break
    return out
