# SPDX-License-Identifier: Apache-2.0
"""The operator's goal as a run takes it: sampled, checked, handed to the goal task.

A run samples its goal source (a scenario's stream, or the teleop page's live
goal) at the source's rate, like an operator's input device. A malformed
sample (NaN, not a rotation) is rejected with an event and the previous goal
stays; a source that raises keeps the previous goal too. Each accepted goal
that differs from the one before is kept with its time, for the trace and for
replay. Whether the goal lies in an obstacle (or in space no camera has seen)
is said as it changes: the arm then stops short of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from cbp.collision.world import CollisionWorld
from cbp.errors import InvalidTargetError
from cbp.goals import GoalSource, LiveGoalSource
from cbp.plugin import GoalReceiver
from cbp.robot import FloatArray
from cbp.run.events import RunLog
from cbp.spatial import checked_se3

__all__ = ["GoalInput"]


@dataclass
class _Sampled:
    t: float = -math.inf
    pose: pin.SE3 | None = None
    changes: list[tuple[float, pin.SE3]] = field(default_factory=list)


class GoalInput:
    """Samples a goal source and hands each accepted goal to the goal task.

    Args:
        source: where the goal comes from (None: the run has no goal).
        task: the scenario's goal task (None: the goal is only recorded).
        log: the run's log, for events.
        world: the collision world whose environment the goal is checked
            against (None: not checked).
        perceived: the world's environment is a camera map (the event then
            names unseen space as a possible reason).
    """

    def __init__(
        self,
        source: GoalSource | None,
        task: GoalReceiver | None,
        log: RunLog,
        world: CollisionWorld | None = None,
        perceived: bool = False,
    ) -> None:
        """Nothing sampled yet."""
        self.source = source
        self.task = task
        self._log = log
        self._world = world
        self._perceived = perceived
        self._sampled = _Sampled()
        self._failing = False
        self._space_checked: tuple[object, FloatArray] = (None, np.zeros(0))
        self._blocked = False

    @property
    def changes(self) -> list[tuple[float, pin.SE3]]:
        """Each accepted goal that differs from the one before, and its time."""
        return self._sampled.changes

    def goal(self, t: float) -> pin.SE3 | None:
        """The goal at time ``t``: the latest valid sample of the source."""
        source = self.source
        if source is None:
            return None
        sample_t = math.floor(t * source.rate_hz + 1e-9) / source.rate_hz
        sampled = self._sampled
        if sample_t <= sampled.t:
            return sampled.pose
        sampled.t = sample_t
        try:
            position, rotation = source.sample(sample_t)
        except Exception as exc:  # a goal source that fails: keep the goal
            if not self._failing:
                self._log.event(
                    t,
                    f"goal input failed ({type(exc).__name__}: {exc}); "
                    "previous goal kept",
                )
            self._failing = True
            return sampled.pose
        if self._failing:
            self._log.event(t, "goal input works again")
            self._failing = False
        try:
            pose = checked_se3(position, rotation, "goal")
        except InvalidTargetError as exc:
            self._log.event(t, f"goal rejected, previous goal kept: {exc}")
        else:
            if sampled.pose is None or not pose.isApprox(sampled.pose, 1e-9):
                sampled.changes.append((sample_t, pose))
            sampled.pose = pose
        return sampled.pose

    def changed(self) -> bool:
        """Whether the source has a goal newer than the last one sampled.

        Only a live source can (:class:`~cbp.goals.LiveGoalSource`); a
        scenario's stream is sampled at its rate.
        """
        return isinstance(self.source, LiveGoalSource) and self.source.changed()

    def send(self, t: float) -> pin.SE3 | None:
        """Sample the goal at ``t`` and hand it to the goal task."""
        pose = self.goal(t)
        if pose is not None:
            if self.task is not None:
                self.task.set_target(pose.translation, pose.rotation)
            self._check_space(t, pose)
        return pose

    def resend(self, t: float) -> pin.SE3 | None:
        """Sample the source again now (not waiting for its rate) and send."""
        self._sampled.t = -math.inf
        return self.send(t)

    def _check_space(self, t: float, pose: pin.SE3) -> None:
        """Say when the goal enters or leaves an obstacle (or unseen space)."""
        world = self._world
        if world is None:
            return
        environment = world.environment
        checked_environment, checked_position = self._space_checked
        if environment is checked_environment and np.array_equal(
            pose.translation, checked_position
        ):
            return
        self._space_checked = (environment, pose.translation.copy())
        blocked = bool(environment.inside(pose.translation[None])[0])
        if blocked == self._blocked:
            return
        self._blocked = blocked
        if not blocked:
            self._log.event(t, "goal is in open space again")
        elif self._perceived:
            self._log.event(
                t,
                "goal lies in an obstacle or in space no camera has seen "
                "(perception.unknown: occupied counts it as an obstacle): the arm "
                "stops short of it",
            )
        else:
            self._log.event(
                t, "goal lies inside an obstacle: the arm stops short of it"
            )
