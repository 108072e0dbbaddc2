# SPDX-License-Identifier: Apache-2.0
"""Frames that lie: a camera's frame checked against what must be in it.

A depth frame can be well formed and still false, and a false frame is worse
than none: the map frees the space the camera says it sees through. A frame
is refused (the camera then counts as giving no valid frame, and a camera
without one for ``perception.camera_timeout`` stops the arm) when

* it reads **nothing up to its far plane** in almost every pixel
  (``perception.max_far_fraction``): a blinded or failed sensor, whose frame
  would clear the map in front of it. A camera on the robot may look into open
  space: its frame is refused only where the map holds obstacles in its view
  (:data:`EXPECTED_IN_VIEW`); a fixed camera, which sees the workcell, always;
* it is **frozen**: the very same image as the camera's last one, while the arm
  moved in its view or the camera moved with the arm (a real sensor's noise
  alone makes two frames differ; a stuck driver repeats its last frame). An
  image with no reading nearer than its far plane is not held frozen: moving
  would not change it;
* a fixed camera **sees through the robot**: where the robot's joints must be
  in the image, most pixels read farther away than the joints
  (``perception.see_through_fraction``, ``see_through_tolerance``): the camera
  was moved or its pose is wrong, and its frame would be mapped in the wrong
  place. An obstacle between the camera and the arm reads nearer, not
  farther, so occlusion does not count.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from cbp.perception.frame import DepthFrame
from cbp.robot import FloatArray

__all__ = ["EXPECTED_IN_VIEW", "FrameCheck", "PlausibilityLimits"]

#: Depth-buffer values from here up read the far plane (nothing seen up to it).
_FAR_PLANE = 1.0 - 1e-6
#: The arm moved when a coordinate changed by more than this [rad or m].
_MOVED = 1e-3
#: A camera moved when its optical centre moved by more than this [m] ...
_CAMERA_MOVED = 1e-3
#: ... or its axes turned by more than this (sum of direction-cosine changes).
_CAMERA_TURNED = 1e-3
#: A camera on the robot that reads nothing up to its far plane is believed
#: unless the map holds obstacles in at least this fraction of its view.
EXPECTED_IN_VIEW = 0.05
#: Robot points in view below this number do not decide whether a camera sees
#: the robot where it must.
_MIN_POINTS = 3


@dataclass(frozen=True)
class PlausibilityLimits:
    """The limits a camera's frames are held to.

    Attributes:
        max_far_fraction: a frame with at least this fraction of its pixels
            reading the far plane is refused (1 or more: never).
        see_through_fraction: a fixed camera's frame is refused when more than
            this fraction of the robot's joints in its view read farther away
            than the joint (1 or more: never).
        see_through_tolerance: how much farther a pixel must read than the
            joint there to count as seeing through it [m].
    """

    max_far_fraction: float = 0.99
    see_through_fraction: float = 0.5
    see_through_tolerance: float = 0.05


class FrameCheck:
    """Checks one camera's frames, each against the one before.

    Args:
        camera: the camera's name, for messages.
        mounted: the camera moves with the robot (it is not expected to see
            the robot's joints at fixed places).
        limits: the limits.
    """

    def __init__(self, camera: str, mounted: bool, limits: PlausibilityLimits):
        """No frame seen yet."""
        self.camera = camera
        self.mounted = mounted
        self.limits = limits
        self._last: tuple[DepthFrame, FloatArray] | None = None
        #: The camera was found frozen, and its image has not changed since.
        self._stuck = False

    def check(
        self,
        frame: DepthFrame,
        q: FloatArray,
        joints: FloatArray,
        in_view: Callable[[DepthFrame], float] | None = None,
    ) -> str | None:
        """Why ``frame`` should not be believed, or None.

        Args:
            frame: the frame (already well formed: :meth:`DepthFrame.problem`).
            q: the robot's configuration when it was taken.
            joints: the robot's joint positions in the world then (n, 3) [m].
            in_view: the fraction of a frame's view in which the map holds
                obstacles (:meth:`OccupancyGrid.occupied_in_view
                <cbp.perception.occupancy.OccupancyGrid.occupied_in_view>`);
                None: every camera's frame that reads nothing is refused.
        """
        last, self._last = self._last, (frame, np.array(q, dtype=float))
        far = float(np.count_nonzero(frame.depth >= _FAR_PLANE)) / frame.depth.size
        if far >= self.limits.max_far_fraction and self.limits.max_far_fraction < 1.0:
            blind = self._blind(frame, far, in_view)
            if blind is not None:
                return blind
        rows, cols, depth = frame.project(np.asarray(joints, dtype=float))
        seen = (rows >= 0) & (depth > frame.closest) & (depth < frame.far)
        if last is not None:
            frozen = self._frozen(frame, q, last, bool(seen.any()))
            if frozen is not None:
                return frozen
        if self.mounted or self.limits.see_through_fraction >= 1.0:
            return None
        return self._sees_through(frame, rows[seen], cols[seen], depth[seen])

    def _blind(
        self,
        frame: DepthFrame,
        far: float,
        in_view: Callable[[DepthFrame], float] | None,
    ) -> str | None:
        """A problem for a frame that reads nothing in ``far`` of its pixels.

        None for a camera on the robot looking where the map holds nothing.
        """
        limit = self.limits.max_far_fraction
        said = (
            f"reads nothing up to its far plane in {far:.1%} of its pixels "
            f"(perception.max_far_fraction: {limit:g})"
        )
        if not self.mounted or in_view is None:
            return f"{said}: a blinded or failed sensor, not believed"
        mapped = in_view(frame)
        if mapped < EXPECTED_IN_VIEW:
            return None  # open space ahead of a camera on the robot
        return (
            f"{said} where the map holds obstacles in {mapped:.0%} of its view: "
            "a blinded or failed sensor, not believed"
        )

    def _frozen(
        self,
        frame: DepthFrame,
        q: FloatArray,
        last: tuple[DepthFrame, FloatArray],
        robot_in_view: bool,
    ) -> str | None:
        """A problem when ``frame`` repeats the last one while something moved.

        A camera found frozen stays so until its image changes: once the arm
        has stopped for it, nothing moves, and its stuck image would be
        believed again (the arm then crept on, stopped and went on).
        """
        before, q_before = last
        if not np.array_equal(frame.depth, before.depth, equal_nan=True):
            self._stuck = False
            return None
        if not np.any(frame.depth < _FAR_PLANE):
            # Nothing up to the far plane anywhere (open space ahead of a
            # camera on the arm): no motion could change the image. A sensor
            # blinded that way is the far-plane check's to refuse.
            return None
        if self._stuck:
            return "frozen: the same image as its last frame since it froze"
        if self.mounted:
            moved = (
                float(np.linalg.norm(frame.position - before.position)) > _CAMERA_MOVED
                or float(np.abs(frame.view[:3, :3] - before.view[:3, :3]).sum())
                > _CAMERA_TURNED
            )
            what = "the camera moved with the arm"
        else:
            moved = robot_in_view and float(np.max(np.abs(q - q_before))) > _MOVED
            what = "the arm moved in its view"
        if not moved:
            return None
        self._stuck = True
        return f"frozen: the same image as its last frame while {what}"

    def _sees_through(
        self, frame: DepthFrame, rows: np.ndarray, cols: np.ndarray, depth: FloatArray
    ) -> str | None:
        """A problem when most joints in view read farther away than they are."""
        if rows.size < _MIN_POINTS:
            return None
        buffer = frame.depth[rows, cols]
        n, f = frame.near, frame.far
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            measured = np.where(
                buffer >= _FAR_PLANE, np.inf, f * n / (f - (f - n) * buffer)
            )
        reading = np.isfinite(buffer)
        if np.count_nonzero(reading) < _MIN_POINTS:
            return None
        through = reading & (measured > depth + self.limits.see_through_tolerance)
        fraction = float(np.count_nonzero(through)) / float(np.count_nonzero(reading))
        if fraction <= self.limits.see_through_fraction:
            return None
        return (
            f"does not see the robot where it must: {np.count_nonzero(through)} of "
            f"{np.count_nonzero(reading)} joints in its view read farther away "
            "than the joint (the camera moved, or its pose is wrong)"
        )
