# SPDX-License-Identifier: Apache-2.0
"""Goal sources: the operator's goal pose as a function of time, one class per kind.

A run samples its goal source at the source's rate, like an operator's input
device (:class:`GoalSource`): a scenario's stream, or an operator's live goal
(:class:`LiveGoal`); a run's parts take any (:func:`cbp.run.build_run`). A
scenario's ``goal:`` section names its kind with ``type:``, and
:data:`GOAL_KINDS` holds one class per kind, each in its own module with the
schema of its section:

* ``keyframes`` (:mod:`.keyframes`): poses at times; translation interpolated
  linearly, rotation by slerp;
* ``step`` (:mod:`.step`): each keyframe's pose held from its time on (a jump);
* ``function`` (:mod:`.function`): position and roll-pitch-yaw as expressions
  of ``t`` (:mod:`cbp.expressions`), e.g. sinusoids;
* ``recorded`` (:mod:`.recorded`): a goal file of timestamped poses, so that an
  operator's session is recorded once and replayed to every method.

The scenario's schema reads the table (:meth:`GoalSpec.variants`). To add a
kind: write ``cbp/goals/<kind>.py`` with a :class:`GoalSpec` subclass (its
``type`` defaulting to the kind's name, its keys documented) and a
:class:`GoalStream` subclass (``type_name``, ``Spec``, ``sample``), and add the
class to :data:`GOAL_KINDS`.
"""

from __future__ import annotations

from pathlib import Path

from cbp.goals.base import GoalSource, GoalSpec, GoalStream, LiveGoalSource, PoseTrack
from cbp.goals.function import FunctionGoal, FunctionGoalSpec, PoseExpressions
from cbp.goals.keyframes import Keyframe, KeyframesGoal, KeyframesGoalSpec
from cbp.goals.live import LiveGoal
from cbp.goals.recorded import (
    RECORDED_COLUMNS,
    RecordedGoal,
    RecordedGoalSpec,
    read_recorded,
    recorded_goal_overrides,
    write_recorded,
)
from cbp.goals.step import StepGoal, StepGoalSpec

__all__ = [
    "GOAL_KINDS",
    "RECORDED_COLUMNS",
    "FunctionGoal",
    "FunctionGoalSpec",
    "GoalSource",
    "GoalSpec",
    "GoalStream",
    "Keyframe",
    "KeyframesGoal",
    "KeyframesGoalSpec",
    "LiveGoal",
    "LiveGoalSource",
    "PoseExpressions",
    "PoseTrack",
    "RecordedGoal",
    "RecordedGoalSpec",
    "StepGoal",
    "StepGoalSpec",
    "goal_stream",
    "read_recorded",
    "recorded_goal_overrides",
    "write_recorded",
]

#: The kinds of a scenario's goal, by ``type:`` name (sorted).
GOAL_KINDS: dict[str, type[GoalStream]] = {
    kind.type_name: kind
    for kind in (FunctionGoal, KeyframesGoal, RecordedGoal, StepGoal)
}


def goal_stream(spec: GoalSpec, folder: Path | None = None) -> GoalStream:
    """The stream of a scenario's ``goal:`` section, of the kind it names.

    Args:
        spec: the section (a kind's :attr:`GoalStream.Spec`).
        folder: where files it names are found (the scenario's folder).

    Raises:
        ConfigError: the section cannot be sampled (location in the section;
            :class:`~cbp.errors.DataFileError` for a file it names).
    """
    return GOAL_KINDS[spec.type](spec, folder)
