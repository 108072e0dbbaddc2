# SPDX-License-Identifier: Apache-2.0
"""The operator's goal as a run takes it: sampled, checked, handed to the goal task.

A run samples its goal source (a scenario's stream, or the teleop page's live
goal) at the source's rate, like an operator's input device. A malformed
sample (NaN, not a rotation) is rejected and the previous goal stays; a source
that raises keeps the previous goal too. Either is said once per episode: when
it starts, and with the count of samples when a valid goal comes again (the
run's counter ``rejected_goal_samples`` holds the total). Each accepted goal
that differs from the one before is kept with its time, for the trace and for
replay. Whether the goal lies in an obstacle (or in space no camera has seen)
is said as it changes: the arm then stops short of it.

An operator's live goal is also held to :class:`GoalBounds`: a goal farther
than :data:`ABSURD` from the origin is refused (the previous goal stays), and
one outside the world's box (``perception.bounds``) or beyond the arm's reach
is clamped onto them; each change is an event.
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
from cbp.scenario.reach import Reach
from cbp.scenario.runtime import Scenario
from cbp.spatial import checked_se3

__all__ = ["ABSURD", "GoalBounds", "GoalInput"]

#: An operator's goal farther than this from the world's origin is refused [m].
ABSURD = 1e3


@dataclass(frozen=True)
class GoalBounds:
    """Where an operator's goal may be: in the world's box and the arm's reach.

    Attributes:
        lower: the box's lower corner (3,) [m].
        upper: its upper corner (3,) [m].
        centre: the arm's first joint, where its reach is measured from (3,)
            [m]; None for a robot whose base moves (no fixed reach).
        reach: how far the goal's frame can be from ``centre`` at most: the
            lengths of the chain's links added up (an upper bound,
            :mod:`cbp.scenario.reach`) [m].
    """

    lower: FloatArray
    upper: FloatArray
    centre: FloatArray | None
    reach: float

    @classmethod
    def of(cls, scenario: Scenario) -> GoalBounds:
        """The bounds of ``scenario``'s robot and world (``perception.bounds``)."""
        bounds = scenario.spec.perception.bounds  # None: the reach bounds it
        lower, upper = (
            np.asarray(c, dtype=float)
            for c in (bounds if bounds is not None else (-np.inf, np.inf))
        )
        reach = scenario.reach()
        if reach is None:
            return cls(lower, upper, None, np.inf)
        return cls(lower, upper, reach.centre, reach.radius)

    def clamp(self, position: FloatArray) -> tuple[FloatArray, str | None]:
        """``position`` moved into the bounds, and what was done (None: nothing)."""
        inside = np.clip(position, self.lower, self.upper)
        said = []
        if not np.array_equal(inside, position):
            said.append(
                f"outside the world's bounds {self.lower.tolist()}..."
                f"{self.upper.tolist()} m (perception.bounds)"
            )
        if self.centre is not None:
            offset = inside - self.centre
            distance = float(np.linalg.norm(offset))
            if distance > self.reach:
                inside = self.centre + offset * (self.reach / distance)
                said.append(
                    f"{distance:.2f} m from the arm's first joint, beyond its reach "
                    f"({self.reach:.2f} m)"
                )
        return inside, "; ".join(said) or None


@dataclass
class _Sampled:
    t: float = -math.inf
    pose: pin.SE3 | None = None
    changes: list[tuple[float, pin.SE3]] = field(default_factory=list)


class _Rejections:
    """Rejected goal samples, said once per episode with their count.

    As deadline misses are (:class:`cbp.run.periods.DeadlineMisses`):
    the first with its reason, at once; the count when a valid goal is taken
    again. The run's counter ``rejected_goal_samples`` holds the total.
    """

    def __init__(self, log: RunLog) -> None:
        self._log = log
        self._since: float | None = None
        self._count = 0

    def rejected(self, t: float, reason: str) -> None:
        """The sample at ``t`` was rejected for ``reason``."""
        counters = self._log.counters
        counters["rejected_goal_samples"] = counters.get("rejected_goal_samples", 0) + 1
        self._count += 1
        if self._since is None:
            self._since = t
            self._log.event(t, f"goal rejected, previous goal kept: {reason}")

    def accepted(self, t: float) -> None:
        """A valid sample was taken at ``t``: the episode, if any, ends."""
        if self._since is None:
            return
        self._log.event(
            t,
            f"goal accepted again after {self._count} rejected sample(s) since "
            f"{self._since:.2f} s",
        )
        self._since = None
        self._count = 0


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
        bounds: where the goal may be (an operator's live goal); None: any
            finite goal is taken as it is (a scenario's stream).
        reach: the arm's reach; a goal beyond it is said to be out of reach
            (an event when it leaves and when it comes back), as the goal
            is taken. Bounds clamp such a goal instead.
    """

    def __init__(
        self,
        source: GoalSource | None,
        task: GoalReceiver | None,
        log: RunLog,
        world: CollisionWorld | None = None,
        perceived: bool = False,
        bounds: GoalBounds | None = None,
        reach: Reach | None = None,
    ) -> None:
        """Nothing sampled yet."""
        self.source = source
        # Asked once: changed() runs at every step of a planner's period.
        self._live = source if isinstance(source, LiveGoalSource) else None
        self.task = task
        self._log = log
        self._world = world
        self._perceived = perceived
        self._sampled = _Sampled()
        self._failing = False
        self._rejections = _Rejections(log)
        self._space_checked: tuple[object, FloatArray] = (None, np.zeros(0))
        self._blocked = False
        self._bounds = bounds
        self._clamped: str | None = None
        self._reach = reach if bounds is None else None
        self._out_of_reach = False

    @property
    def changes(self) -> list[tuple[float, pin.SE3]]:
        """Each accepted goal that differs from the one before, and its time.

        Times strictly increase: of goals taken within one sample, the last.
        """
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
            if self._bounds is not None:
                pose = self._bounded(t, pose)
        except InvalidTargetError as exc:
            self._rejections.rejected(t, str(exc))
        else:
            self._rejections.accepted(t)
            if sampled.pose is None or not pose.isApprox(sampled.pose, 1e-9):
                changes = sampled.changes
                if changes and changes[-1][0] >= sample_t:
                    # A goal taken again within one sample (a live goal that
                    # moved twice): the later one is the goal at that time, so
                    # the recorded times stay strictly increasing (replayable).
                    changes[-1] = (changes[-1][0], pose)
                else:
                    changes.append((sample_t, pose))
            sampled.pose = pose
        return sampled.pose

    def _bounded(self, t: float, pose: pin.SE3) -> pin.SE3:
        """``pose`` within the bounds; an absurd one raises InvalidTargetError."""
        assert self._bounds is not None
        far = float(np.max(np.abs(pose.translation)))
        if far > ABSURD:
            raise InvalidTargetError(
                f"goal {far:.3g} m from the world's origin (more than {ABSURD:g} m)"
            )
        position, said = self._bounds.clamp(pose.translation)
        if said != self._clamped:
            self._log.event(
                t,
                f"goal clamped: {said}; the arm goes for the nearest point within"
                if said is not None
                else "goal within the world's bounds and the arm's reach again",
            )
            self._clamped = said
        return pin.SE3(pose.rotation, position) if said is not None else pose

    def changed(self) -> bool:
        """Whether the source has a goal newer than the last one sampled.

        Only a live source can (:class:`~cbp.goals.LiveGoalSource`); a
        scenario's stream is sampled at its rate.
        """
        return self._live is not None and self._live.changed()

    def send(self, t: float) -> pin.SE3 | None:
        """Sample the goal at ``t`` and hand it to the goal task."""
        pose = self.goal(t)
        if pose is not None:
            if self.task is not None:
                self.task.set_target(pose.translation, pose.rotation)
            self._check_space(t, pose)
            self._check_reach(t, pose)
        return pose

    def resend(self, t: float) -> pin.SE3 | None:
        """Sample the source again now (not waiting for its rate) and send."""
        self._sampled.t = -math.inf
        return self.send(t)

    def _check_reach(self, t: float, pose: pin.SE3) -> None:
        """Say when the goal leaves the arm's reach, and when it is back."""
        if self._reach is None:
            return
        beyond = self._reach.beyond(pose.translation)
        if (beyond is not None) == self._out_of_reach:
            return
        self._out_of_reach = beyond is not None
        self._log.event(
            t,
            "goal within the arm's reach again"
            if beyond is None
            else f"goal out of reach: {beyond}; the arm stops short of it",
        )

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
