# SPDX-License-Identifier: Apache-2.0
"""Goal streams: the operator's goal pose as a function of time.

A stream is sampled at the command rate (30 Hz by default), like an operator's
input device. Kinds: ``keyframes`` (poses at times; translation interpolated
linearly and rotation by slerp) and ``step`` (each keyframe's pose held from its
time on: a jump).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import pinocchio as pin

from cbp.errors import ConfigError
from cbp.spatial import Pose


@dataclass(frozen=True, kw_only=True)
class Keyframe:
    """A goal pose at a time."""

    t: float
    """Time [s] from the start of the run."""
    pose: Pose
    """The goal pose, world frame."""


@dataclass(frozen=True, kw_only=True)
class GoalSpec:
    """The ``goal:`` section of a scenario."""

    type: Literal["keyframes", "step"]
    """``keyframes``: interpolate between poses; ``step``: jump at each time."""
    task: str | None = None
    """Name of the task entry that receives the goal (default: the first
    ``goal_pose`` task)."""
    rate_hz: float = 30.0
    """Rate at which the goal is sampled and sent [Hz]."""
    keyframes: list[Keyframe] = field(default_factory=list)
    """Poses at times, in increasing time order."""

    def __post_init__(self) -> None:
        """At least one keyframe, times increasing, positive rate."""
        if not self.rate_hz > 0:
            raise ConfigError(f"must be > 0, got {self.rate_hz}", "rate_hz")
        if not self.keyframes:
            raise ConfigError("at least one keyframe is needed", "keyframes")
        times = [k.t for k in self.keyframes]
        for i in range(1, len(times)):
            if times[i] <= times[i - 1]:
                raise ConfigError(
                    f"times must increase; {times[i]} follows {times[i - 1]}",
                    f"keyframes[{i}].t",
                )


class GoalStream:
    """Samples a :class:`GoalSpec`: ``pose(t)`` returns the goal at time t."""

    def __init__(self, spec: GoalSpec) -> None:
        """Convert the keyframes once."""
        self.spec = spec
        self.period = 1.0 / spec.rate_hz
        self._times = [k.t for k in spec.keyframes]
        self._poses = [k.pose.to_se3() for k in spec.keyframes]

    def pose(self, t: float) -> pin.SE3:
        """The goal at time ``t`` [s]: held before the first and after the last."""
        i = bisect.bisect_right(self._times, t)
        if i == 0:
            return self._poses[0]
        if i == len(self._times) or self.spec.type == "step":
            return self._poses[i - 1]
        t0, t1 = self._times[i - 1], self._times[i]
        s = (t - t0) / (t1 - t0)
        a, b = self._poses[i - 1], self._poses[i]
        position = (1.0 - s) * a.translation + s * b.translation
        rotation = a.rotation.dot(pin.exp3(s * pin.log3(a.rotation.T.dot(b.rotation))))
        return pin.SE3(rotation, np.asarray(position))
