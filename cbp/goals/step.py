# SPDX-License-Identifier: Apache-2.0
"""``type: step``: goal poses at times, each held from its time on (a jump)."""

from __future__ import annotations

from dataclasses import dataclass

from cbp.goals.keyframes import KeyframesGoal, KeyframesGoalSpec

__all__ = ["StepGoal", "StepGoalSpec"]


@dataclass(frozen=True, kw_only=True)
class StepGoalSpec(KeyframesGoalSpec):
    """``type: step``: poses at times, each held from its time on (a jump)."""

    type: str = "step"


class StepGoal(KeyframesGoal):
    """Samples a ``step`` section: the latest keyframe's pose, held."""

    type_name = "step"
    Spec = StepGoalSpec
    hold = True
