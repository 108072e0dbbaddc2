# SPDX-License-Identifier: Apache-2.0
"""What a camera would see from a pose: the prediction a look is chosen by.

A point is in sight when it lies within the camera's field of view and range
and the line to it is clear: no occupied cell of the map on it, and no part of
the robot (as it stands when the camera looks) in the way. Unseen cells on the
line may be free or not; a line that crosses a length ``u`` of unseen space
reaches its point with a chance of ``exp(-u / UNSEEN_DEPTH)``. So a point at
the edge of what is seen (the frontier) counts fully, and one deep in unseen
space, perhaps behind a surface no camera has mapped yet, counts little: a
look is chosen for what it will reveal, not for what it would see were all
unseen space empty.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin

from cbp.perception.kernels import OCCUPIED, UNKNOWN
from cbp.perception.spec import CameraSpec
from cbp.robot import FloatArray

__all__ = ["UNSEEN_DEPTH", "visibility"]

#: The length of unseen space a line of sight crosses with a chance 1/e [m].
UNSEEN_DEPTH = 0.05


def visibility(
    camera: pin.SE3,
    spec: CameraSpec,
    points: FloatArray,
    state_at: Callable[[FloatArray], np.ndarray],
    cell: float,
    body: Callable[[FloatArray], np.ndarray] | None = None,
) -> FloatArray:
    """The chance (n,) that a camera at ``camera`` (optical frame) sees ``points``.

    0 outside its field of view (the spec's vertical angle, its image's
    aspect) and range, behind an occupied cell or behind the robot; else
    ``exp(-u / UNSEEN_DEPTH)`` for the length ``u`` of unseen cells on the
    line. The point's own cell and the one before it do not count.

    Args:
        camera: the camera's optical pose (+z along its axis).
        spec: the camera.
        points: the points (n, 3).
        state_at: a map's cell states of points (m, 3).
        cell: the map's cell size [m].
        body: which points (m, 3) lie within the robot where the camera looks
            from (None: nothing of the robot in the way). Points nearer the
            camera than its ``near`` are not asked: the camera sits on the
            robot.
    """
    local = (points - camera.translation) @ camera.rotation  # into the camera
    z = local[:, 2]
    half = np.tan(np.deg2rad(spec.fov_deg) / 2.0)
    aspect = spec.width / spec.height
    with np.errstate(divide="ignore", invalid="ignore"):
        inside = (
            (z > spec.near)
            & (z < spec.far)
            & (np.abs(local[:, 1] / z) < half)
            & (np.abs(local[:, 0] / z) < half * aspect)
        )
    out = np.zeros(len(points))
    if not inside.any():
        return out
    eye = camera.translation
    d = points[inside] - eye
    length = np.linalg.norm(d, axis=1)
    k = max(2, int(np.max(length) / (0.5 * cell)))
    ts = np.linspace(0.0, 1.0, k)
    along = eye + ts[None, :, None] * d[:, None, :]
    at = ts[None, :] * length[:, None]  # distance from the eye [m]
    before = at < length[:, None] - 1.5 * cell
    state = state_at(along.reshape(-1, 3)).reshape(len(d), k)
    blocked = np.any((state == OCCUPIED) & before, axis=1)
    if body is not None:
        asked = before & (at > spec.near) & ~blocked[:, None]
        hit = np.zeros_like(asked)
        hit[asked] = body(along[asked])
        blocked |= np.any(hit, axis=1)
    step = length / (k - 1)  # the samples' spacing on each line [m]
    unseen = np.count_nonzero((state == UNKNOWN) & before, axis=1) * step
    out[inside] = np.where(blocked, 0.0, np.exp(-unseen / UNSEEN_DEPTH))
    return out
