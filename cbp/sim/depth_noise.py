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
        z = np.asarray(buffer, dtype=float)
        out = z.copy()
        hit = z < far_plane  # a reading nearer than the far plane (NaN: False)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            d = far * near / (far - (far - near) * z[hit])
            lost = None
            if noise.edge_jump > 0.0:
                depth = np.full(z.shape, np.inf)
                depth[hit] = d
                # Background beside an object lies inf beyond it: lost too.
                # A pixel without a reading (NaN) neither loses nor makes lose.
                lost = np.zeros(z.shape, dtype=bool)
                step = depth[:, 1:] - depth[:, :-1]
                lost[:, 1:] |= step > noise.edge_jump
                lost[:, :-1] |= step < -noise.edge_jump
                step = depth[1:, :] - depth[:-1, :]
                lost[1:, :] |= step > noise.edge_jump
                lost[:-1, :] |= step < -noise.edge_jump
            d += noise.sigma(d) * self._rng.standard_normal(d.size, dtype=np.float32)
            noisy = far / (far - near) * (1.0 - near / d)
            noisy[(d >= far) | (d <= 0.0)] = np.nan  # out of range
            out[hit] = noisy
        if lost is not None:
            out[lost] = np.nan
        if noise.dropout > 0.0:
            count = self._rng.binomial(z.size, noise.dropout)
            out.reshape(-1)[self._rng.choice(z.size, count, replace=False)] = np.nan
        return np.asarray(out)
