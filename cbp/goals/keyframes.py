# SPDX-License-Identifier: Apache-2.0
"""``type: keyframes``: goal poses at times, interpolated between them."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cbp.errors import ConfigError
from cbp.goals.base import GoalSpec, GoalStream, PoseTrack
from cbp.robot import FloatArray
from cbp.spatial import Pose

__all__ = ["Keyframe", "KeyframesGoal", "KeyframesGoalSpec"]


@dataclass(frozen=True, kw_only=True)
class Keyframe:
    """A goal pose at a time."""

    t: float
    """Time [s] from the start of the run."""
    pose: Pose
    """The goal pose, world frame."""


@dataclass(frozen=True, kw_only=True)
class KeyframesGoalSpec(GoalSpec):
    """``type: keyframes``: poses at times, interpolated between them.

    Translation linearly, rotation by slerp; the first pose is held before its
    time and the last after it.
    """

    type: str = "keyframes"
    keyframes: list[Keyframe]
    """Poses at times, in increasing time order."""

    def __post_init__(self) -> None:
        """At least one keyframe; times increase."""
        super().__post_init__()
        if not self.keyframes:
            raise ConfigError("needs at least one keyframe", "keyframes")
        times = [k.t for k in self.keyframes]
        for i in range(1, len(times)):
            if times[i] <= times[i - 1]:
                raise ConfigError(
                    f"times must increase; {times[i]} follows {times[i - 1]}",
                    f"keyframes[{i}].t",
                )


class KeyframesGoal(GoalStream):
    """Samples a ``keyframes`` section: the poses interpolated at any time.

    Args:
        spec: the section.
        folder: unused (no file).
    """

    type_name = "keyframes"
    Spec = KeyframesGoalSpec
    #: Each keyframe's pose is held from its time on (``step``).
    hold = False

    def __init__(self, spec: KeyframesGoalSpec, folder: Path | None = None) -> None:
        """Convert the keyframes' poses once."""
        super().__init__(spec, folder)
        placements = [k.pose.to_se3() for k in spec.keyframes]
        self.track = PoseTrack(
            [k.t for k in spec.keyframes],
            [np.array(M.translation) for M in placements],
            [np.array(M.rotation) for M in placements],
            hold=self.hold,
        )

    @property
    def end_time(self) -> float:
        """Time of the last keyframe [s]."""
        return self.track.times[-1]

    def sample(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Goal position (3,) [m] and rotation (3, 3) at time ``t`` [s], world frame."""
        return self.track.at(t)
